//! The 2D element: the virtual tension tests return E and nu at every
//! aspect ratio (shear: mss-validate's `plane` tests); rigid motions give no force; forces are minus the
//! energy's gradient where the model is conservative; momentum is
//! conserved; the static and the damped dynamic answers agree; results do
//! not depend on the thread count; hourglass control makes elongated cells
//! stable in bending.

use hexmesh::plane::RectLattice;
use mss_core::plane::{PlaneModel, PlaneParameterization, PlaneProblem};
use mss_core::{Material, Vec3};

use crate::on_threads;

const VARIANTS: [PlaneParameterization; 2] =
    [PlaneParameterization::Paper, PlaneParameterization::Areal];
const RATIOS: [f64; 5] = [1.0, 2.0, 4.0, 0.5, 0.25];
const NUS: [f64; 5] = [0.0, 0.25, 0.3, 0.45, 0.49];

fn model(
    n: [u32; 2],
    cell: [f64; 2],
    nu: f64,
    variant: PlaneParameterization,
    hourglass: Option<f64>,
) -> PlaneModel {
    let lattice = RectLattice::block(n, cell, [0.0, 0.0]).unwrap();
    let material = Material::with_poisson_range(1.0e4, nu, 1000.0, -1.0, 0.5).unwrap();
    PlaneModel::new(&lattice, material, 0.01, variant, hourglass).unwrap()
}

/// Uniaxial tension along `axis` of a block with rollers on the low faces:
/// (E, nu) measured from the mean displacements of the high faces.
fn tension(model: PlaneModel, axis: usize, stress: f64) -> (f64, f64) {
    let other = 1 - axis;
    let rest = model.rest_positions().to_vec();
    let hi = |d: usize| rest.iter().map(|p| p[d]).fold(f64::MIN, f64::max);
    let [l0, h0] = model.cell_size();
    let face_length = [h0, l0];
    let t = model.thickness();
    let mut p = PlaneProblem::new(model);
    let (len, width) = (hi(axis), hi(other));
    for (i, x) in rest.iter().enumerate() {
        for d in 0..2 {
            if x[d].abs() < 1e-12 {
                p.held[i][d] = true;
            }
        }
        if (x[axis] - len).abs() < 1e-12 {
            // Consistent loads: half of each cell face's force to each node.
            let mut share = face_length[axis];
            if x[other].abs() < 1e-12 || (x[other] - width).abs() < 1e-12 {
                share *= 0.5;
            }
            p.forces[i][axis] = stress * share * t;
        }
    }
    let mut x = rest.clone();
    p.solve_static(0.0, &mut x).unwrap();
    let mean = |d: usize, at: f64, along: usize| {
        let (s, n) = rest
            .iter()
            .zip(&x)
            .filter(|(r, _)| (r[along] - at).abs() < 1e-12)
            .fold((0.0, 0), |(s, n), (r, x)| (s + x[d] - r[d], n + 1));
        s / n as f64
    };
    let eps_axis = mean(axis, len, axis) / len;
    let eps_other = mean(other, width, other) / width;
    (stress / eps_axis, -eps_other / eps_axis)
}

#[test]
fn the_virtual_tension_tests_return_e_and_nu_at_every_aspect_ratio() {
    for variant in VARIANTS {
        for ratio in RATIOS {
            for nu in NUS {
                for axis in 0..2 {
                    let m = model([4, 3], [0.01 * ratio, 0.01], nu, variant, None);
                    let (e, measured_nu) = tension(m, axis, 1e-3);
                    let tag = format!("{variant:?} l0/h0 = {ratio} nu = {nu} axis {axis}");
                    assert!((e / 1.0e4 - 1.0).abs() < 1e-5, "{tag}: E = {e}");
                    assert!((measured_nu - nu).abs() < 1e-5, "{tag}: nu = {measured_nu}");
                }
            }
        }
    }
}

#[test]
fn the_papers_printed_correction_size_misses_nu_and_twice_it_does_not() {
    // docs/model.md, section 9: the printed F_perp is half of ours.
    let lattice = RectLattice::block([4, 3], [0.01, 0.01], [0.0, 0.0]).unwrap();
    for (nu, printed_nu) in [(0.3, 0.3226), (0.45, 0.3762)] {
        let material = Material::new(1.0e4, nu, 1000.0).unwrap();
        let ours =
            PlaneModel::new(&lattice, material, 0.01, PlaneParameterization::Paper, None).unwrap();
        let mut c = ours.coefficients();
        c.c_xy /= 2.0;
        c.c_yx /= 2.0;
        let printed = PlaneModel::with_coefficients(&lattice, material, 0.01, c).unwrap();
        assert!((tension(ours, 0, 1e-3).1 - nu).abs() < 1e-5);
        let measured = tension(printed, 0, 1e-3).1;
        assert!((measured - printed_nu).abs() < 1e-3, "nu {nu}: {measured}");
    }
}

#[test]
fn springs_alone_reproduce_nu_only_at_one_third() {
    let exact = tension(
        model(
            [4, 3],
            [0.01, 0.01],
            1.0 / 3.0,
            PlaneParameterization::Springs,
            None,
        ),
        0,
        1e-3,
    );
    assert!((exact.1 - 1.0 / 3.0).abs() < 1e-5, "{exact:?}");
    let off = tension(
        model(
            [4, 3],
            [0.01, 0.01],
            0.45,
            PlaneParameterization::Springs,
            None,
        ),
        0,
        1e-3,
    );
    assert!((off.1 - 0.45).abs() > 0.05, "{off:?}");
}

fn deformed(model: &PlaneModel, amplitude: f64) -> Vec<Vec3> {
    model
        .rest_positions()
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let s = (i as f64 * 1.7).sin();
            let c = (i as f64 * 0.9).cos();
            p + Vec3::new(amplitude * s, amplitude * c, 0.0)
        })
        .collect()
}

#[test]
fn rigid_motions_give_no_force() {
    for variant in [
        PlaneParameterization::Paper,
        PlaneParameterization::Springs,
        PlaneParameterization::Areal,
    ] {
        let m = model([3, 2], [0.04, 0.01], 0.3, variant, Some(1.0));
        let (s, c) = 0.7f64.sin_cos();
        let x: Vec<Vec3> = m
            .rest_positions()
            .iter()
            .map(|p| Vec3::new(c * p.x - s * p.y + 0.3, s * p.x + c * p.y - 1.0, 0.0))
            .collect();
        let mut f = vec![Vec3::zeros(); x.len()];
        m.internal_forces(&x, &mut f);
        let scale = m.coefficients().k_d * 0.01;
        assert!(
            f.iter().all(|v| v.norm() < 1e-9 * scale),
            "{variant:?}: {:?}",
            f.iter().map(|v| v.norm()).fold(0.0, f64::max)
        );
    }
}

#[test]
fn forces_are_minus_the_gradient_of_the_energy_where_conservative() {
    for variant in [PlaneParameterization::Springs, PlaneParameterization::Areal] {
        for hourglass in [None, Some(1.0)] {
            let m = model([3, 2], [0.04, 0.01], 0.2, variant, hourglass);
            let x = deformed(&m, 2e-3);
            let mut f = vec![Vec3::zeros(); x.len()];
            m.internal_forces(&x, &mut f);
            let step = 1e-7;
            let scale = f.iter().map(|v| v.norm()).fold(0.0, f64::max);
            for i in 0..x.len() {
                for d in 0..2 {
                    let mut plus = x.clone();
                    plus[i][d] += step;
                    let mut minus = x.clone();
                    minus[i][d] -= step;
                    let g = (m.energy(&plus) - m.energy(&minus)) / (2.0 * step);
                    assert!(
                        (f[i][d] + g).abs() < 1e-6 * scale,
                        "{variant:?} {hourglass:?} node {i} dof {d}: force {} gradient {g}",
                        f[i][d]
                    );
                }
            }
        }
    }
}

#[test]
fn the_forces_sum_to_zero_and_conservative_ones_exert_no_torque() {
    for variant in [
        PlaneParameterization::Paper,
        PlaneParameterization::Springs,
        PlaneParameterization::Areal,
    ] {
        let m = model([3, 3], [0.02, 0.01], 0.4, variant, Some(1.0));
        let x = deformed(&m, 3e-3);
        let mut f = vec![Vec3::zeros(); x.len()];
        m.internal_forces(&x, &mut f);
        let scale = f.iter().map(|v| v.norm()).sum::<f64>();
        let total: Vec3 = f.iter().sum();
        assert!(total.norm() < 1e-12 * scale, "{variant:?}: {total:?}");
        if variant != PlaneParameterization::Paper {
            let torque: f64 = x.iter().zip(&f).map(|(p, f)| p.x * f.y - p.y * f.x).sum();
            assert!(torque.abs() < 1e-12 * scale, "{variant:?}: torque {torque}");
        }
    }
}

#[test]
fn a_free_body_keeps_its_momentum_while_it_vibrates() {
    let m = model(
        [4, 2],
        [0.02, 0.01],
        0.3,
        PlaneParameterization::Paper,
        Some(1.0),
    );
    let dt = m.stable_time_step(0.5);
    let masses = m.masses().to_vec();
    let p = PlaneProblem::new(m);
    let mut x = deformed(&p.model, 1e-3);
    let mut v: Vec<Vec3> = (0..x.len()).map(|_| Vec3::new(0.3, -0.2, 0.0)).collect();
    let momentum = |v: &[Vec3]| -> Vec3 { v.iter().zip(&masses).map(|(v, m)| v * *m).sum() };
    let before = momentum(&v);
    p.step_explicit(0.0, &mut x, &mut v, dt, 2000).unwrap();
    let after = momentum(&v);
    assert!(
        (after - before).norm() < 1e-12 * before.norm(),
        "{before:?} -> {after:?}"
    );
}

/// A cantilever `n` cells long, clamped at x = 0, under gravity along -y,
/// Young's modulus `e`.
fn cantilever(n: [u32; 2], cell: [f64; 2], e: f64, variant: PlaneParameterization) -> PlaneProblem {
    let lattice = RectLattice::block(n, cell, [0.0, 0.0]).unwrap();
    let material = Material::new(e, 0.3, 1000.0).unwrap();
    let m = PlaneModel::new(&lattice, material, 0.01, variant, Some(1.0)).unwrap();
    let mut p = PlaneProblem::new(m);
    for (i, r) in p.model.rest_positions().iter().enumerate() {
        if r.x.abs() < 1e-12 {
            p.held[i] = [true, true];
        }
    }
    p.gravity = [0.0, -9.81];
    p
}

fn tip_sag(p: &PlaneProblem, x: &[Vec3]) -> f64 {
    p.model
        .rest_positions()
        .iter()
        .zip(x)
        .map(|(r, x)| r.y - x.y)
        .fold(f64::MIN, f64::max)
}

#[test]
fn static_and_damped_dynamic_answers_agree() {
    let p = {
        let mut p = cantilever([8, 2], [0.02, 0.02], 1.0e7, PlaneParameterization::Paper);
        p.damping = 40.0;
        p
    };
    let mut xs = p.model.rest_positions().to_vec();
    p.solve_static(0.0, &mut xs).unwrap();
    let mut x = p.model.rest_positions().to_vec();
    let mut v = vec![Vec3::zeros(); x.len()];
    let dt = p.model.stable_time_step(0.8);
    p.step_explicit(0.0, &mut x, &mut v, dt, (2.0 / dt) as usize)
        .unwrap();
    let (s, d) = (tip_sag(&p, &xs), tip_sag(&p, &x));
    assert!(s > 1e-4, "sag {s}");
    assert!((s - d).abs() < 1e-3 * s, "static {s}, dynamic {d}");
}

#[test]
fn results_do_not_depend_on_the_thread_count() {
    let p = cantilever([12, 3], [0.02, 0.01], 1.0e7, PlaneParameterization::Paper);
    let run = || {
        let mut x = p.model.rest_positions().to_vec();
        p.solve_static(0.0, &mut x).unwrap();
        let mut v = vec![Vec3::zeros(); x.len()];
        p.step_explicit(0.0, &mut x, &mut v, 1e-5, 50).unwrap();
        x
    };
    let one = on_threads(1, run);
    for threads in [2, 3] {
        assert_eq!(one, on_threads(threads, run), "{threads} threads");
    }
}

/// The smallest eigenvalue of the rest stiffness on the free dofs, scaled
/// by the largest.
fn smallest_stiffness(p: &PlaneProblem) -> f64 {
    let k = p.model.tangent(p.model.rest_positions());
    let free: Vec<usize> = (0..p.model.num_nodes())
        .flat_map(|i| (0..2).map(move |d| (i, d)))
        .filter(|&(i, d)| !p.held[i][d])
        .map(|(i, d)| 2 * i + d)
        .collect();
    let n = free.len();
    let mut dense = nalgebra::DMatrix::<f64>::zeros(n, n);
    for (a, &ra) in free.iter().enumerate() {
        for (b, &rb) in free.iter().enumerate() {
            if let Some(j) = k.find(ra / 2, rb / 2) {
                dense[(a, b)] = -k.blocks[j][(ra % 2, rb % 2)];
            }
        }
    }
    let sym = (&dense + dense.transpose()) * 0.5;
    let eig = sym.symmetric_eigenvalues();
    let max = eig.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    eig.iter().fold(f64::MAX, |m, v| m.min(*v)) / max
}

#[test]
fn hourglass_control_makes_elongated_cells_stable_in_bending() {
    // One cell thick, cells four times longer than high: k_l < 0.
    let lattice = RectLattice::block([6, 1], [0.04, 0.01], [0.0, 0.0]).unwrap();
    let material = Material::new(1.0e5, 0.3, 1000.0).unwrap();
    for (hourglass, stable) in [(None, false), (Some(1.0), true)] {
        let m = PlaneModel::new(
            &lattice,
            material,
            0.01,
            PlaneParameterization::Paper,
            hourglass,
        )
        .unwrap();
        assert!(m.coefficients().k_l < 0.0);
        let mut p = PlaneProblem::new(m);
        for (i, r) in p.model.rest_positions().iter().enumerate() {
            if r.x.abs() < 1e-12 {
                p.held[i] = [true, true];
            }
        }
        let lowest = smallest_stiffness(&p);
        assert_eq!(lowest > 0.0, stable, "{hourglass:?}: lowest {lowest}");
    }
}

#[test]
fn a_cantilever_converges_towards_timoshenko_under_refinement() {
    // 0.4 x 0.04 m, E = 1e9 Pa (a sag of 0.06 % of the length: linear),
    // nu = 0.3, t = 0.01 m, its own weight.
    let (len, height, t): (f64, f64, f64) = (0.4, 0.04, 0.01);
    let e = 1.0e9;
    let g = e / 2.6;
    let w = 1000.0 * 9.81 * height * t; // N/m along the beam
    let i = t * height.powi(3) / 12.0;
    let timoshenko =
        w * len.powi(4) / (8.0 * e * i) + w * len * len / (2.0 * 5.0 / 6.0 * g * height * t);
    let mut errors = Vec::new();
    for k in [1u32, 2, 4] {
        let p = cantilever(
            [10 * k, k],
            [len / (10 * k) as f64, height / k as f64],
            e,
            PlaneParameterization::Paper,
        );
        let mut x = p.model.rest_positions().to_vec();
        p.solve_static(0.0, &mut x).unwrap();
        let sag = tip_sag(&p, &x);
        errors.push(sag / timoshenko - 1.0);
    }
    eprintln!("tip sag against Timoshenko's, relative errors at 1, 2, 4 cells through: {errors:?}");
    assert!(errors.iter().all(|e| e.abs() < 0.01), "{errors:?}");
}

/// A free 8 x 4 block (0.16 x 0.08 m) on the ground line y = 0.
fn block_on(
    obstacle: mss_core::plane::PlaneObstacle,
    friction: f64,
    gravity: [f64; 2],
) -> PlaneProblem {
    let lattice = RectLattice::block([8, 4], [0.02, 0.02], [0.0, 0.0]).unwrap();
    let material = Material::new(1.0e6, 0.3, 1000.0).unwrap();
    let m = PlaneModel::new(
        &lattice,
        material,
        0.01,
        PlaneParameterization::Paper,
        Some(1.0),
    )
    .unwrap();
    let stiffness = 1.0e5;
    let mut p = PlaneProblem::new(m);
    p.gravity = gravity;
    p.contact = Some(
        mss_core::plane::PlaneContact::uniform(
            vec![obstacle],
            Vec::new(),
            mss_core::plane::PlaneContactSettings::elastic(stiffness, friction),
        )
        .unwrap(),
    );
    p
}

#[test]
fn a_block_rests_on_the_ground_carrying_its_weight() {
    use mss_core::plane::PlaneObstacle;
    let ground = PlaneObstacle::HalfPlane {
        point: [0.0, 0.0],
        normal: [0.0, 1.0],
    };
    let mut p = block_on(ground, 0.5, [0.0, -9.81]);
    // Statics has no friction: one roller keeps the block from sliding away.
    p.held[0] = [true, false];
    let mut x = p.model.rest_positions().to_vec();
    p.solve_static(0.0, &mut x).unwrap();
    p.held[0] = [false, false];
    let weight = p.model.total_mass() * 9.81;
    let carried: f64 = x.iter().filter(|q| q.y < 0.0).map(|q| -q.y * 1.0e5).sum();
    assert!(
        (carried - weight).abs() < 1e-6 * weight,
        "{carried} vs {weight}"
    );
    // The same at rest after a damped fall from 1 cm.
    p.damping = 30.0;
    let mut x: Vec<Vec3> = p
        .model
        .rest_positions()
        .iter()
        .map(|q| q + Vec3::new(0.0, 0.01, 0.0))
        .collect();
    let mut v = vec![Vec3::zeros(); x.len()];
    let dt = p.stable_time_step(0.8);
    p.step_explicit(0.0, &mut x, &mut v, dt, (1.5 / dt) as usize)
        .unwrap();
    let carried: f64 = x.iter().filter(|q| q.y < 0.0).map(|q| -q.y * 1.0e5).sum();
    assert!(
        (carried - weight).abs() < 1e-3 * weight,
        "{carried} vs {weight}"
    );
}

#[test]
fn a_block_on_a_slope_slides_at_the_coulomb_rate_or_sticks() {
    use mss_core::plane::PlaneObstacle;
    // Gravity turned by the slope's angle; the ground stays y = 0.
    for (tan, mu, slides) in [(0.8, 0.5, true), (0.3, 0.5, false)] {
        let angle: f64 = f64::atan(tan);
        let g = [9.81 * angle.sin(), -9.81 * angle.cos()];
        let ground = PlaneObstacle::HalfPlane {
            point: [0.0, 0.0],
            normal: [0.0, 1.0],
        };
        let mut p = block_on(ground, mu, g);
        p.damping = 0.0;
        // Start at rest in equilibrium with the ground: settle the normal
        // load without the slope's pull first.
        let mut x = p.model.rest_positions().to_vec();
        let mut settle = p.clone();
        settle.gravity = [0.0, g[1]];
        settle.held[0] = [true, false];
        settle.solve_static(0.0, &mut x).unwrap();
        let x0: f64 = x.iter().map(|q| q.x).sum::<f64>() / x.len() as f64;
        let mut v = vec![Vec3::zeros(); x.len()];
        let dt = p.stable_time_step(0.5);
        let t = 0.3;
        p.step_explicit(0.0, &mut x, &mut v, dt, (t / dt) as usize)
            .unwrap();
        let moved = x.iter().map(|q| q.x).sum::<f64>() / x.len() as f64 - x0;
        let rigid = 0.5 * 9.81 * (angle.sin() - mu * angle.cos()) * t * t;
        if slides {
            assert!(
                (moved / rigid - 1.0).abs() < 0.05,
                "tan {tan}: moved {moved}, rigid {rigid}"
            );
        } else {
            assert!(moved.abs() < 1e-4, "tan {tan}: moved {moved}");
        }
    }
}

/// A block on slopes whose kinetic friction (0.3) is below its static one
/// (0.6), in both time integrators. At tan 0.25 it sticks at rest, and
/// pushed down the slope at 0.5 m/s it slows at `g (sin - mu_k cos)` (at
/// the static coefficient it would stop within 0.15 s). At tan 0.5,
/// between the two, it keeps speeding up at that rate once pushed. (At
/// rest there it slips too: the tilt comes at once, and the body's shear
/// wave asks its bottom twice the slope's pull, more than `mu_s` holds;
/// kinetic friction then cannot stop it. Physics, not a defect.)
#[test]
fn kinetic_friction_below_the_static_one_sets_the_sliding_rate() {
    use mss_core::plane::{PlaneContact, PlaneContactSettings, PlaneObstacle};
    let ground = PlaneObstacle::HalfPlane {
        point: [0.0, 0.0],
        normal: [0.0, 1.0],
    };
    let mean_x = |x: &[Vec3]| x.iter().map(|q| q.x).sum::<f64>() / x.len() as f64;
    for (tan, pushes) in [(0.25, [0.0, 0.5]), (0.5, [0.5, 1.0])] {
        let angle = f64::atan(tan);
        let g = [9.81 * angle.sin(), -9.81 * angle.cos()];
        let mut p = block_on(ground, 0.6, g);
        let settings = PlaneContactSettings {
            friction_kinetic: 0.3,
            damping_ratio: 0.2,
            ..PlaneContactSettings::elastic(1.0e5, 0.6)
        };
        p.contact = Some(PlaneContact::uniform(vec![ground], Vec::new(), settings).unwrap());
        let mut settled = p.model.rest_positions().to_vec();
        let mut settle = p.clone();
        settle.gravity = [0.0, g[1]];
        settle.held[0] = [true, false];
        settle.solve_static(0.0, &mut settled).unwrap();
        for implicit in [false, true] {
            for push in pushes {
                let mut x = settled.clone();
                let mut v = vec![Vec3::new(push, 0.0, 0.0); x.len()];
                let dt = p.stable_time_step(0.5) * if implicit { 4.0 } else { 1.0 };
                let steps = (0.3 / dt).round() as usize;
                if implicit {
                    p.step_implicit(0.0, &mut x, &mut v, dt, steps).unwrap();
                } else {
                    p.step_explicit(0.0, &mut x, &mut v, dt, steps).unwrap();
                }
                let t = steps as f64 * dt;
                let moved = mean_x(&x) - mean_x(&settled);
                let what =
                    format!("tan {tan}, implicit {implicit}, push {push} m/s: moved {moved} m");
                if push == 0.0 {
                    assert!(moved.abs() < 1e-4, "{what}");
                } else {
                    let a = 9.81 * (angle.sin() - 0.3 * angle.cos());
                    let rigid = push * t + 0.5 * a * t * t;
                    assert!((moved / rigid - 1.0).abs() < 0.03, "{what}, rigid {rigid}");
                }
            }
        }
    }
}

/// A block dropped 1 cm onto the ground with no damping in the body: with
/// elastic contact it keeps its energy and bounces back; the contact's
/// damper (a ratio of 1) takes the bounce out; neither gains energy.
#[test]
fn contact_damping_takes_the_bounce_out_of_a_drop() {
    use mss_core::plane::{PlaneContact, PlaneContactSettings, PlaneObstacle};
    let ground = PlaneObstacle::HalfPlane {
        point: [0.0, 0.0],
        normal: [0.0, 1.0],
    };
    // A contact softer than the block (9 nodes touch: 18 kN/m against the
    // block's 20 kN/m in compression), so that its damper, not the body,
    // decides the bounce.
    let stiffness = 2.0e3;
    let mut bounces = Vec::new();
    for zeta in [0.0, 1.0] {
        let mut p = block_on(ground, 0.0, [0.0, -9.81]);
        let settings = PlaneContactSettings {
            damping_ratio: zeta,
            ..PlaneContactSettings::elastic(stiffness, 0.0)
        };
        p.contact = Some(PlaneContact::uniform(vec![ground], Vec::new(), settings).unwrap());
        let energy = |x: &[Vec3], v: &[Vec3]| {
            let masses = p.model.masses();
            let kinetic: f64 = (0..x.len())
                .map(|i| 0.5 * masses[i] * v[i].norm_squared())
                .sum();
            let height: f64 = (0..x.len()).map(|i| masses[i] * 9.81 * x[i].y).sum();
            let penalty: f64 = x
                .iter()
                .map(|q| 0.5 * stiffness * q.y.min(0.0).powi(2))
                .sum();
            kinetic + height + penalty + p.model.energy(x)
        };
        let mut x: Vec<Vec3> = p
            .model
            .rest_positions()
            .iter()
            .map(|q| q + Vec3::new(0.0, 0.01, 0.0))
            .collect();
        let mut v = vec![Vec3::zeros(); x.len()];
        let start = energy(&x, &v);
        let dt = p.stable_time_step(0.5);
        let lowest = |x: &[Vec3]| x.iter().map(|q| q.y).fold(f64::INFINITY, f64::min);
        let (mut t, mut touched, mut rebound) = (0.0, false, f64::NEG_INFINITY);
        while t < 0.25 {
            p.step_explicit(t, &mut x, &mut v, dt, 20).unwrap();
            t += 20.0 * dt;
            let e = energy(&x, &v);
            assert!(e < start * 1.01 + 1e-9, "zeta {zeta}: energy {e} > {start}");
            touched |= lowest(&x) < 0.0;
            if touched {
                rebound = rebound.max(lowest(&x));
            }
        }
        let end = energy(&x, &v);
        if zeta == 0.0 {
            assert!(
                end > 0.9 * start,
                "elastic contact lost energy: {end} of {start}"
            );
        }
        bounces.push(rebound);
    }
    // Elastic: the block leaves the ground again by millimetres.
    assert!(bounces[0] > 2e-3, "{bounces:?}");
    assert!(bounces[1] < 0.3 * bounces[0], "{bounces:?}");
}

#[test]
fn the_implicit_step_settles_at_the_static_equilibrium_with_large_steps() {
    let mut p = cantilever([8, 2], [0.02, 0.02], 1.0e7, PlaneParameterization::Paper);
    p.damping = 5.0;
    let mut xs = p.model.rest_positions().to_vec();
    p.solve_static(0.0, &mut xs).unwrap();
    let mut x = p.model.rest_positions().to_vec();
    let mut v = vec![Vec3::zeros(); x.len()];
    // 100 times the explicit limit: stable, and damped to rest.
    let dt = 100.0 * p.model.stable_time_step(1.0);
    let iterations = p.step_implicit(0.0, &mut x, &mut v, dt, 400).unwrap();
    assert!(iterations > 0);
    let (s, d) = (tip_sag(&p, &xs), tip_sag(&p, &x));
    assert!((s - d).abs() < 1e-3 * s, "static {s}, implicit {d}");
    assert!(v.iter().all(|v| v.norm() < 1e-3), "not at rest");
}

/// A strip held at x = 0 and stretched by a motion of its far end: the
/// moved nodes follow the ramp exactly in both time integrators, and the
/// damped dynamic runs end at the static solve of the motion's end (which
/// puts them exactly there), where the strip is in uniaxial tension
/// between its clamps: its mid-height nodes stretched by u * x / L.
#[test]
fn moved_nodes_follow_their_ramp_and_the_runs_end_at_the_static_answer() {
    use mss_core::plane::PlaneMotion;
    let model = model(
        [8, 2],
        [0.02, 0.02],
        0.0,
        PlaneParameterization::Paper,
        None,
    );
    let rest = model.rest_positions().to_vec();
    let length = 0.16;
    let mut p = PlaneProblem::new(model);
    let far: Vec<u32> = (0..rest.len() as u32)
        .filter(|&i| (rest[i as usize].x - length).abs() < 1e-12)
        .collect();
    for (i, r) in rest.iter().enumerate() {
        if r.x.abs() < 1e-12 {
            p.held[i] = [true, true];
        }
    }
    for &n in &far {
        p.held[n as usize] = [true, true];
    }
    let u = 2e-3;
    p.motions.push(PlaneMotion {
        nodes: far.clone(),
        displacement: [u, 0.0],
        ramp: 0.1,
    });
    p.damping = 40.0;
    let mut xs = rest.clone();
    p.solve_static(1.0, &mut xs).unwrap();
    for &n in &far {
        assert_eq!(xs[n as usize].x, rest[n as usize].x + u);
    }
    // nu = 0: no lateral contraction for the clamps to hinder, so the
    // strain is uniform up to the model's nonlinearity at 1.25 % strain.
    for (r, x) in rest.iter().zip(&xs) {
        assert!(
            (x.x - r.x - u * r.x / length).abs() < 1e-3 * u,
            "{r:?} {x:?}"
        );
        assert!((x.y - r.y).abs() < 1e-3 * u, "{r:?} {x:?}");
    }
    let dt = 0.5 * p.stable_time_step(1.0);
    let steps = (0.5 / dt) as usize;
    for implicit in [false, true] {
        let mut x = rest.clone();
        let mut v = vec![Vec3::zeros(); x.len()];
        let dt = if implicit { 20.0 * dt } else { dt };
        let steps = if implicit { steps / 20 } else { steps };
        let mut t = 0.0;
        // In chunks, as a run writes frames: the time goes on across them.
        for chunk in [steps / 3, steps / 3, steps - 2 * (steps / 3)] {
            if implicit {
                p.step_implicit(t, &mut x, &mut v, dt, chunk).unwrap();
            } else {
                p.step_explicit(t, &mut x, &mut v, dt, chunk).unwrap();
            }
            t += chunk as f64 * dt;
            let share = (t / 0.1).min(1.0);
            for &n in &far {
                let n = n as usize;
                assert!((x[n].x - rest[n].x - share * u).abs() < 1e-15, "t = {t}");
            }
        }
        let worst = x
            .iter()
            .zip(&xs)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(worst < 1e-3 * u, "implicit {implicit}: {worst}");
    }
}

/// Two materials in series (`with_regions`): a bar of nu = 0 whose right
/// half is 4 times stiffer and 3 times denser, pulled at its end, stretches
/// by F L1 / (E1 A) + F L2 / (E2 A); its mass is each half's.
#[test]
fn materials_in_series_stretch_as_springs_in_series() {
    let (n, cell) = ([8u32, 2u32], [0.02, 0.02]);
    let base = model(n, cell, 0.0, PlaneParameterization::Paper, None);
    let soft = base.material();
    let stiff = Material::with_poisson_range(4.0 * soft.young, 0.0, 3000.0, -1.0, 0.5).unwrap();
    let rest = base.rest_positions().to_vec();
    let length = 0.16;
    let cell_material: Vec<u32> = base
        .cells()
        .iter()
        .map(|c| {
            let x = c.iter().map(|&a| rest[a as usize].x).sum::<f64>() / 4.0;
            u32::from(x > 0.5 * length)
        })
        .collect();
    let model = base.with_regions(None, &[stiff], cell_material).unwrap();
    let (width, t) = (0.04, model.thickness());
    let expected_mass = (soft.density + stiff.density) * 0.5 * length * width * t;
    assert!((model.total_mass() - expected_mass).abs() < 1e-12 * expected_mass);
    let mut p = PlaneProblem::new(model);
    let force = 1e-3 * soft.young * width * t;
    for (i, r) in rest.iter().enumerate() {
        if r.x.abs() < 1e-12 {
            p.held[i] = [true, true];
        }
        if (r.x - length).abs() < 1e-12 {
            // Consistent loads: the edge nodes carry half a cell face.
            let share = if r.y.abs() < 1e-12 || (r.y - width).abs() < 1e-12 {
                0.25
            } else {
                0.5
            };
            p.forces[i][0] = force * share;
        }
    }
    let mut x = rest.clone();
    p.solve_static(0.0, &mut x).unwrap();
    let end: Vec<f64> = rest
        .iter()
        .zip(&x)
        .filter(|(r, _)| (r.x - length).abs() < 1e-12)
        .map(|(r, x)| x.x - r.x)
        .collect();
    let mean = end.iter().sum::<f64>() / end.len() as f64;
    let area = width * t;
    let series =
        force * 0.5 * length / (soft.young * area) + force * 0.5 * length / (stiff.young * area);
    assert!(
        (mean - series).abs() < 2e-3 * series,
        "{mean} against {series}"
    );
}

/// Moving obstacles in the plane, in the explicit and the implicit step: a
/// block on the ground pushed sideways by a moving box is carried at least
/// as far as the box goes and never passes through it; a conveyor (the ground moving along itself) carries a block
/// by friction, which acts on the velocity relative to the ground's; a
/// disc pressed into a block along its path ends where the static solve,
/// following the path with its increments, puts it.
#[test]
fn moving_obstacles_push_and_carry_a_block() {
    use mss_core::contact::Path;
    use mss_core::plane::{PlaneContact, PlaneContactSettings, PlaneObstacle};
    let ground = PlaneObstacle::HalfPlane {
        point: [0.0, 0.0],
        normal: [0.0, 1.0],
    };
    let block = |obstacles: Vec<PlaneObstacle>, paths: Vec<Path>, friction: f64| {
        let m = model(
            [4, 2],
            [0.02, 0.02],
            0.3,
            PlaneParameterization::Paper,
            Some(1.0),
        );
        let mut p = PlaneProblem::new(m);
        p.gravity = [0.0, -9.81];
        p.damping = 5.0;
        p.contact = Some(
            PlaneContact::uniform(
                obstacles,
                paths,
                PlaneContactSettings::elastic(1.0e5, friction),
            )
            .unwrap(),
        );
        p
    };
    let key = |t: f64, dx: f64| (t, Vec3::new(dx, 0.0, 0.0));
    // The box's right side starts 1 mm left of the block and moves 3 cm.
    let pusher = PlaneObstacle::Rect {
        min: [-0.05, 0.005],
        max: [-0.001, 0.035],
    };
    let push = Path::new(vec![key(0.0, 0.0), key(0.3, 0.03)]).unwrap();
    let p = block(vec![ground, pusher], vec![Path::fixed(), push.clone()], 0.3);
    let dt = 0.5 * p.stable_time_step(1.0);
    for implicit in [false, true] {
        let mut x = p.model.rest_positions().to_vec();
        let mut v = vec![Vec3::zeros(); x.len()];
        let (dt, chunk) = if implicit { (4.0 * dt, 25) } else { (dt, 100) };
        let mut t = 0.0;
        while t < 0.6 {
            if implicit {
                p.step_implicit(t, &mut x, &mut v, dt, chunk).unwrap();
            } else {
                p.step_explicit(t, &mut x, &mut v, dt, chunk).unwrap();
            }
            t += chunk as f64 * dt;
            // The nodes facing the box are in it by no more than the
            // penalty's give under the push's start (about 2 mm here).
            let face = -0.001 + push.offset(t).x;
            let facing = x
                .iter()
                .filter(|p| p.y > 0.005 && p.y < 0.035)
                .map(|p| p.x)
                .fold(f64::INFINITY, f64::min);
            assert!(
                facing > face - 3e-3,
                "implicit {implicit}, t = {t}: {facing} behind {face}"
            );
        }
        let left = x.iter().map(|p| p.x).fold(f64::INFINITY, f64::min);
        assert!(left > 0.029 - 3e-3, "implicit {implicit}: {left}");
    }
    // The conveyor: 0.1 m/s from t = 0 (the block slips about a
    // millimetre while friction, mu = 0.5, brings it up to speed).
    let belt = Path::new(vec![key(0.0, 0.0), key(1.0, 0.1)]).unwrap();
    let p = block(vec![ground], vec![belt], 0.5);
    for implicit in [false, true] {
        let mut x = p.model.rest_positions().to_vec();
        let mut v = vec![Vec3::zeros(); x.len()];
        // The implicit steps' Newton stalls where a node's contact switches
        // within a step: those steps are taken again in halves.
        let dt = if implicit { 4.0 * dt } else { dt };
        let steps = (0.6 / dt) as usize;
        if implicit {
            p.step_implicit(0.0, &mut x, &mut v, dt, steps).unwrap();
        } else {
            p.step_explicit(0.0, &mut x, &mut v, dt, steps).unwrap();
        }
        let rest = p.model.rest_positions();
        let moved = x.iter().zip(rest).map(|(a, b)| a.x - b.x).sum::<f64>() / x.len() as f64;
        assert!(
            (moved - 0.059).abs() < 0.05 * 0.059,
            "implicit {implicit}: carried {moved}"
        );
    }
    // A disc pressed 4 mm into the top of a block held at its base: the
    // static solve follows the disc down its path with the load increments
    // and ends where the damped explicit run does.
    let disc = PlaneObstacle::Disc {
        centre: [0.04, 0.07],
        radius: 0.03,
    };
    let down = Path::new(vec![
        (0.0, Vec3::zeros()),
        (0.2, Vec3::new(0.0, -0.004, 0.0)),
    ])
    .unwrap();
    let mut p = block(vec![disc], vec![down], 0.0);
    p.gravity = [0.0, 0.0];
    p.damping = 60.0;
    let rest = p.model.rest_positions().to_vec();
    for (i, r) in rest.iter().enumerate() {
        if r.y.abs() < 1e-12 {
            p.held[i] = [true, true];
        }
    }
    let mut xs = rest.clone();
    p.solve_static(0.5, &mut xs).unwrap();
    let top = |x: &[Vec3]| {
        rest.iter()
            .zip(x)
            .map(|(r, x)| x.y - r.y)
            .fold(f64::INFINITY, f64::min)
    };
    assert!(top(&xs) < -0.002, "pressed {}", top(&xs));
    let mut x = rest.clone();
    let mut v = vec![Vec3::zeros(); x.len()];
    let dt = 0.5 * p.stable_time_step(1.0);
    p.step_explicit(0.0, &mut x, &mut v, dt, (0.5 / dt) as usize)
        .unwrap();
    assert!(
        (top(&x) - top(&xs)).abs() < 0.01 * top(&xs).abs(),
        "explicit {} static {}",
        top(&x),
        top(&xs)
    );
}

/// `with_regions` refuses materials that do not fit the lattice.
#[test]
fn regions_that_do_not_fit_are_refused() {
    let m = || {
        model(
            [2, 1],
            [0.02, 0.02],
            0.3,
            PlaneParameterization::Paper,
            None,
        )
    };
    let other = m().material();
    let short = m().with_regions(None, &[other], vec![0]).unwrap_err();
    assert!(
        short.to_string().contains("1 cell materials for 2 cells"),
        "{short}"
    );
    let missing = m().with_regions(None, &[other], vec![0, 2]).unwrap_err();
    assert!(
        missing.to_string().contains("names material 2"),
        "{missing}"
    );
}

/// A strip (nu = 0) held at x = 0 and dragged at its far face toward a
/// target 1 cm beyond it: the strip and the drag spring in series, so the
/// face moves `K d / (K + k_s)` with `k_s = E t H / L`; the static solve,
/// the damped explicit and the implicit runs agree; a free body dragged
/// whole goes rigidly to the target.
#[test]
fn a_drag_spring_pulls_in_series_with_the_strip() {
    use mss_core::constraints::{Face, NodeSelector};
    use mss_core::plane::PlaneDrag;
    use std::sync::Arc;
    let lattice = RectLattice::block([8, 2], [0.02, 0.02], [0.0, 0.0]).unwrap();
    let material = Material::new(1.0e5, 0.0, 1000.0).unwrap();
    let model =
        PlaneModel::new(&lattice, material, 0.01, PlaneParameterization::Paper, None).unwrap();
    let strip_stiffness = 1.0e5 * 0.01 * 0.04 / 0.16;
    let drag_stiffness = strip_stiffness;
    let face = model.select_nodes(&NodeSelector::face(Face::XMax)).unwrap();
    let held = model.select_nodes(&NodeSelector::face(Face::XMin)).unwrap();
    let drag = PlaneDrag::new(&model, face.clone(), [0.17, 0.02], drag_stiffness).unwrap();
    let mut p = PlaneProblem::new(model);
    for &n in &held {
        p.held[n as usize] = [true, true];
    }
    p.loads.push(Arc::new(drag));
    p.damping = 60.0;
    let face_x =
        |x: &[Vec3]| face.iter().map(|&n| x[n as usize].x - 0.16).sum::<f64>() / face.len() as f64;
    let series = drag_stiffness * 0.01 / (drag_stiffness + strip_stiffness);
    let mut xs = p.model.rest_positions().to_vec();
    p.solve_static(0.0, &mut xs).unwrap();
    assert!(
        (face_x(&xs) / series - 1.0).abs() < 0.02,
        "static {} vs {series}",
        face_x(&xs)
    );
    let mut x = p.model.rest_positions().to_vec();
    let mut v = vec![Vec3::zeros(); x.len()];
    let dt = p.stable_time_step(0.8);
    p.step_explicit(0.0, &mut x, &mut v, dt, (1.0 / dt) as usize)
        .unwrap();
    assert!(
        (face_x(&x) - face_x(&xs)).abs() < 1e-3 * face_x(&xs),
        "explicit {} static {}",
        face_x(&x),
        face_x(&xs)
    );
    let mut x = p.model.rest_positions().to_vec();
    let mut v = vec![Vec3::zeros(); x.len()];
    p.step_implicit(0.0, &mut x, &mut v, 0.01, 100).unwrap();
    assert!(
        (face_x(&x) - face_x(&xs)).abs() < 1e-3 * face_x(&xs),
        "implicit {} static {}",
        face_x(&x),
        face_x(&xs)
    );
    // Free and dragged whole: a rigid move to the target, no strain.
    let mut free = PlaneProblem::new(p.model.clone());
    let all: Vec<u32> = (0..free.model.num_nodes() as u32).collect();
    free.loads.push(Arc::new(
        PlaneDrag::new(&free.model, all, [0.1, 0.05], 10.0).unwrap(),
    ));
    let mut x = free.model.rest_positions().to_vec();
    free.solve_static(0.0, &mut x).unwrap();
    for (q, r) in x.iter().zip(free.model.rest_positions()) {
        assert!(
            (q - r - Vec3::new(0.02, 0.03, 0.0)).norm() < 1e-9,
            "{q:?} from {r:?}"
        );
    }
    // Bad values are typed errors.
    assert!(PlaneDrag::new(&free.model, vec![], [0.0; 2], 1.0).is_err());
    assert!(PlaneDrag::new(&free.model, vec![0], [0.0; 2], -1.0).is_err());
    assert!(PlaneDrag::new(&free.model, vec![9999], [0.0; 2], 1.0).is_err());
}

/// A lattice above the direct solver's size (4,000 free dofs), of cells
/// twice as long as high: the multigrid-preconditioned Krylov solve and
/// the sparse LU give the same static answer (within Newton's tolerance)
/// and the same implicit steps.
#[test]
fn multigrid_and_direct_solves_agree_in_2d() {
    use mss_core::solver::LinearSolverKind;
    let mut p = cantilever([60, 40], [0.02, 0.01], 1.0e6, PlaneParameterization::Paper);
    let free = p.held.iter().filter(|h| !h[0]).count() * 2;
    assert!(free > 4000, "{free}");
    let mut answers = Vec::new();
    for kind in [LinearSolverKind::Iterative, LinearSolverKind::Direct] {
        p.linear_solver = kind;
        let mut x = p.model.rest_positions().to_vec();
        p.solve_static(0.0, &mut x).unwrap();
        let mut y = p.model.rest_positions().to_vec();
        let mut v = vec![Vec3::zeros(); y.len()];
        p.step_implicit(0.0, &mut y, &mut v, 0.01, 3).unwrap();
        answers.push((x, y));
    }
    let sag = tip_sag(&p, &answers[1].0);
    assert!(sag > 1e-3, "{sag}");
    for k in 0..2 {
        let (a, b) = if k == 0 {
            (&answers[0].0, &answers[1].0)
        } else {
            (&answers[0].1, &answers[1].1)
        };
        let diff = a
            .iter()
            .zip(b)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(diff < 1e-6 * sag, "{k}: {diff} against a sag of {sag}");
    }
}

/// The single-precision force pass: on the cantilever, the explicit damped
/// run's tip sag in f32 is the f64 one's within 1e-4 (the corners taken
/// relative to each cell's first, the sums in f64), and a body moved a
/// kilometre away gives the same forces.
#[test]
fn the_f32_force_pass_costs_little_accuracy() {
    use mss_core::Precision;
    let mut p = cantilever([16, 4], [0.01, 0.01], 1.0e6, PlaneParameterization::Paper);
    p.damping = 60.0;
    let dt = p.stable_time_step(0.9);
    let mut sags = Vec::new();
    for precision in [Precision::F64, Precision::F32] {
        p.precision = precision;
        let mut x = p.model.rest_positions().to_vec();
        let mut v = vec![Vec3::zeros(); x.len()];
        p.step_explicit(0.0, &mut x, &mut v, dt, (0.5 / dt) as usize)
            .unwrap();
        sags.push(tip_sag(&p, &x));
    }
    assert!(sags[0] > 1e-4, "{sags:?}");
    assert!((sags[1] / sags[0] - 1.0).abs() < 1e-4, "{sags:?}");
    // Far from the origin: the same forces.
    let x: Vec<Vec3> = p
        .model
        .rest_positions()
        .iter()
        .enumerate()
        .map(|(i, r)| r + Vec3::new(1e-4 * (i % 3) as f64, 1e-4 * (i % 5) as f64, 0.0))
        .collect();
    let far: Vec<Vec3> = x
        .iter()
        .map(|q| q + Vec3::new(1000.0, -1000.0, 0.0))
        .collect();
    let (mut f, mut g, mut h) = (
        vec![Vec3::zeros(); x.len()],
        vec![Vec3::zeros(); x.len()],
        vec![Vec3::zeros(); x.len()],
    );
    p.model.internal_forces_with(&x, &mut f, Precision::F32);
    p.model.internal_forces_with(&far, &mut g, Precision::F32);
    p.model.internal_forces_with(&x, &mut h, Precision::F64);
    let scale = h.iter().map(|v| v.norm()).fold(0.0, f64::max);
    for i in 0..x.len() {
        assert!((f[i] - g[i]).norm() < 1e-3 * scale, "node {i}");
        assert!((f[i] - h[i]).norm() < 1e-3 * scale, "node {i}");
    }
}

/// The tangent (the cell's forces on dual numbers) is the forces' central
/// difference quotient, on a sheared and stretched lattice, every variant.
#[test]
fn the_tangent_is_the_derivative_of_the_forces() {
    for variant in [
        PlaneParameterization::Paper,
        PlaneParameterization::Springs,
        PlaneParameterization::Areal,
    ] {
        let m = model([3, 2], [0.02, 0.01], 0.3, variant, Some(1.0));
        let x: Vec<Vec3> = m
            .rest_positions()
            .iter()
            .map(|r| {
                Vec3::new(
                    1.1 * r.x + 0.2 * r.y,
                    0.9 * r.y + 0.05 * r.x * r.x / 0.02,
                    0.0,
                )
            })
            .collect();
        let k = m.tangent(&x);
        let n = x.len();
        let step = 1e-7;
        for j in 0..n {
            for d in 0..2 {
                let (mut plus, mut minus) = (x.clone(), x.clone());
                plus[j][d] += step;
                minus[j][d] -= step;
                let (mut fp, mut fm) = (vec![Vec3::zeros(); n], vec![Vec3::zeros(); n]);
                m.internal_forces(&plus, &mut fp);
                m.internal_forces(&minus, &mut fm);
                for i in 0..n {
                    let quotient = (fp[i] - fm[i]) / (2.0 * step);
                    let exact = k.find(i, j).map_or(Vec3::zeros(), |b| {
                        Vec3::new(k.blocks[b][(0, d)], k.blocks[b][(1, d)], 0.0)
                    });
                    assert!(
                        (quotient - exact).norm() < 1e-5 * (1.0 + exact.norm()),
                        "{variant:?} d f_{i} / d x_{j}[{d}]: {exact:?} vs {quotient:?}"
                    );
                }
            }
        }
    }
}

/// Cells longer than `sqrt(2 + 3 nu)` times their height, without
/// hourglass control, make a lattice unstable in bending (its edge springs
/// negative); hourglass control or squarer cells do not.
#[test]
fn long_cells_without_hourglass_control_are_unstable_in_bending() {
    for (ratio, hourglass, unstable) in [
        (4.0, None, true),
        (2.0, None, true),
        (1.5, None, false),
        (4.0, Some(1.0), false),
        (0.25, None, true),
    ] {
        let lattice = RectLattice::block([4, 2], [0.01 * ratio, 0.01], [0.0, 0.0]).unwrap();
        let material = Material::new(1.0e6, 0.3, 1000.0).unwrap();
        let m = PlaneModel::new(
            &lattice,
            material,
            0.01,
            PlaneParameterization::Paper,
            hourglass,
        )
        .unwrap();
        assert_eq!(
            m.unstable_in_bending(),
            unstable,
            "ratio {ratio}, {hourglass:?}"
        );
    }
}
