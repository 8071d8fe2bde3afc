//! Static equilibria are tested for stability, and a stable one is where a
//! long damped dynamic run ends (docs/robustness.md: the large-load bar).

use hexmesh::Lattice;
use mss_core::constraints::{ConstraintSpec, Face, NodeSelector};
use mss_core::loads::{Damping, ForceDistribution, LoadSpec};
use mss_core::model::{HourglassControl, SpringsOnly, VolumetricBarrier};
use mss_core::solver::{
    Explicit, ExplicitOptions, Integrator, Problem, SolverError, Stability, State, StaticOptions,
    solve_static,
};
use mss_core::{Material, Model, Parameterization};

/// A bar 0.2 x 0.04 x 0.04 m of 20 x 4 x 4 cells, E = 100 kPa, nu = 0.3,
/// the x- face clamped, gravity and 0.05 N down on the x+ face.
fn bar(param: &dyn Parameterization, damping: f64) -> Problem {
    bar_refined(param, damping, 1)
}

/// [`bar`] with `refine` times as many cells along each axis.
fn bar_refined(param: &dyn Parameterization, damping: f64, refine: u32) -> Problem {
    let lattice = Lattice::block(
        [20 * refine, 4 * refine, 4 * refine],
        0.01 / f64::from(refine),
        [0.0; 3],
    )
    .unwrap();
    let model = Model::new(&lattice, Material::new(1.0e5, 0.3, 1000.0).unwrap(), param).unwrap();
    Problem::from_specs(
        model,
        &[ConstraintSpec::fixed(NodeSelector::face(Face::XMin))],
        &[
            LoadSpec::Gravity {
                g: [0.0, 0.0, -9.81],
            },
            LoadSpec::Force {
                select: NodeSelector::face(Face::XMax),
                force: [0.0, 0.0, -0.05],
                distribution: ForceDistribution::default(),
            },
        ],
        Damping {
            alpha: damping,
            beta: 0.0,
        },
    )
    .unwrap()
}

fn max_displacement(problem: &Problem, state: &State) -> f64 {
    state
        .displacements(problem.model())
        .iter()
        .map(|u| u.norm())
        .fold(0.0, f64::max)
}

#[test]
fn an_unstable_equilibrium_is_refused_unless_accepted() {
    let problem = bar(&SpringsOnly, 0.0);
    let mut state = State::at_rest(problem.model());
    let err = solve_static(&problem, &mut state, &StaticOptions::default()).unwrap_err();
    assert_eq!(
        err,
        SolverError::UnstableEquilibrium {
            hourglass_control: false
        }
    );
    // Springs alone have no hourglass control: the message says so, and
    // names no front end's key.
    let text = err.to_string();
    assert!(text.contains("use hourglass control"), "{text}");
    assert!(!text.contains("[solver]") && !text.contains("::"), "{text}");
    let mut state = State::at_rest(problem.model());
    let opts = StaticOptions {
        accept_unstable: true,
        ..StaticOptions::default()
    };
    let info = solve_static(&problem, &mut state, &opts).unwrap();
    assert_eq!(info.stability, Stability::Unstable);
    assert!(max_displacement(&problem, &state) > 0.05);
}

#[test]
fn static_and_damped_dynamics_agree_on_a_stable_equilibrium() {
    let param = HourglassControl::new(Box::new(VolumetricBarrier), 1.0).unwrap();
    let problem = bar(&param, 20.0);
    let mut stat = State::at_rest(problem.model());
    let info = solve_static(&problem, &mut stat, &StaticOptions::default()).unwrap();
    assert_eq!(info.stability, Stability::Stable);
    let mut dynamic = State::at_rest(problem.model());
    let mut integ = Explicit::new(&problem, ExplicitOptions::default()).unwrap();
    while dynamic.time < 3.0 {
        integ.step(&problem, &mut dynamic).unwrap();
    }
    let umax = max_displacement(&problem, &stat);
    assert!(umax > 0.05, "a large deflection: {umax}");
    let worst = stat
        .x
        .iter()
        .zip(&dynamic.x)
        .map(|(a, b)| (a - b).norm())
        .fold(0.0, f64::max);
    assert!(
        worst <= 0.02 * umax,
        "static and dynamic differ by {:.2} % of max |u|",
        100.0 * worst / umax
    );
}

/// The referee of the stability test: a Cholesky factorization of the
/// symmetric part of the stiffness on the free dofs, shifted by round-off.
fn cholesky_says_stable(problem: &Problem, state: &State) -> bool {
    let k = problem.model().stiffness(&state.x);
    let mut sym = k.clone();
    for row in 0..k.num_rows() {
        for idx in k.row_offsets[row] as usize..k.row_offsets[row + 1] as usize {
            let col = k.col_indices[idx] as usize;
            let mirror = k.find(col, row).unwrap();
            sym.blocks[idx] = (k.blocks[idx] + k.blocks[mirror].transpose()) * 0.5;
        }
    }
    sym.add_diagonal(-1e-10 * sym.max_diagonal());
    let fixed: Vec<[bool; 3]> = (0..problem.model().num_nodes())
        .map(|n| problem.constraints().mask(n))
        .collect();
    match sym.factor_cholesky(&fixed) {
        Ok(_) => true,
        Err(mss_core::LinearSolveError::NotPositiveDefinite { .. }) => false,
        Err(e) => panic!("{e}"),
    }
}

#[test]
fn the_lanczos_stability_test_of_large_problems_agrees_with_cholesky() {
    // The bar refined twice: 3,321 nodes, about 9,800 free dofs, above the
    // size where the stability test stops factoring. Dead loads only, so
    // the stiffness is the model's.
    let default = HourglassControl::new(Box::new(VolumetricBarrier), 1.0).unwrap();
    for (param, expected) in [
        (&SpringsOnly as &dyn Parameterization, Stability::Unstable),
        (&default, Stability::Stable),
    ] {
        let problem = bar_refined(param, 0.0, 2);
        let mut state = State::at_rest(problem.model());
        let opts = StaticOptions {
            accept_unstable: true,
            ..StaticOptions::default()
        };
        let info = solve_static(&problem, &mut state, &opts).unwrap();
        assert_eq!(info.stability, expected, "{}", param.name());
        let referee = if cholesky_says_stable(&problem, &state) {
            Stability::Stable
        } else {
            Stability::Unstable
        };
        assert_eq!(info.stability, referee, "{}", param.name());
    }
}
