//! The explicit step's control (docs/robustness.md): a block compressed to
//! 30 % of its height and released, free, runs to the end with the default
//! model, the sub-step shrinking while the barrier is stiff and growing back
//! as the block recovers, no cell folded at a corner; the same for any
//! thread count.

use hexmesh::Lattice;
use mss_core::loads::Damping;
use mss_core::model::{HourglassControl, VolumetricBarrier};
use mss_core::solver::{Explicit, ExplicitOptions, Integrator, Problem, State};
use mss_core::{Material, Model};

fn compressed_block() -> (Problem, State) {
    let lattice = Lattice::block([8, 8, 8], 0.01, [0.0; 3]).unwrap();
    let param = HourglassControl::new(Box::new(VolumetricBarrier), 1.0).unwrap();
    let model = Model::new(
        &lattice,
        Material::new(1.0e4, 0.45, 1000.0).unwrap(),
        &param,
    )
    .unwrap();
    let problem = Problem::new(model)
        .with_damping(Damping {
            alpha: 5.0,
            beta: 0.0,
        })
        .unwrap();
    let mut state = State::at_rest(problem.model());
    for x in &mut state.x {
        x.z *= 0.3;
    }
    (problem, state)
}

/// Runs 0.3 s; the final state and the sub-step counts of every step.
fn release(threads: usize) -> (State, Vec<u32>) {
    crate::on_threads(threads, || {
        let (problem, mut state) = compressed_block();
        let mut integ = Explicit::new(&problem, ExplicitOptions::default()).unwrap();
        let steps = (0.3 / integ.dt()).ceil() as usize;
        let mut substeps = Vec::new();
        for _ in 0..steps {
            substeps.push(integ.step(&problem, &mut state).unwrap().substeps);
        }
        (state, substeps)
    })
}

#[test]
fn a_compressed_block_released_recovers_with_a_controlled_step() {
    let (problem, start) = compressed_block();
    let model = problem.model();
    let (state, substeps) = release(2);
    assert!(model.inverted_cells(&state.x).is_empty());
    // Free and unloaded: the momentum stays zero (mass damping keeps it so).
    let p = state.momentum(model.masses());
    let scale = model.total_mass() * 1.0;
    assert!(p.norm() < 1e-9 * scale, "momentum {p:?}");
    // Damped: no energy appears.
    let energy = |s: &State| model.energy(&s.x) + s.kinetic_energy(model.masses());
    assert!(energy(&state) < energy(&start));
    // The block expands back toward its height.
    let height = |s: &State| {
        let (lo, hi) = s.x.iter().fold((f64::MAX, f64::MIN), |(lo, hi), x| {
            (lo.min(x.z), hi.max(x.z))
        });
        hi - lo
    };
    assert!(height(&state) > 0.8 * 0.08, "height {}", height(&state));
    // The step shrank where the compressed barrier was stiff (by at least
    // the square root of the stiffness growth, less half the safety margin),
    // and came back as the block recovered.
    let growth = model.stiffness_growth(&start.x);
    assert!(growth > 5.0, "growth at 30 % height {growth}");
    let first = substeps[0];
    assert!(
        f64::from(first) >= (growth * 0.9).sqrt(),
        "first step in {first} sub-steps"
    );
    let most = *substeps.iter().max().unwrap();
    let last = *substeps.last().unwrap();
    assert!(
        last < most,
        "last step in {last} sub-steps (at most {most})"
    );
    // Still ringing at 0.3 s, its corners dip into the corner barrier's
    // range (below 0.2), which keeps every one of them unfolded.
    assert!(model.folded_cells(&state.x).is_empty());
}

#[test]
fn the_controlled_step_does_not_depend_on_the_thread_count() {
    let (a, sa) = release(1);
    let (b, sb) = release(2);
    assert_eq!(sa, sb);
    assert_eq!(a.x, b.x);
    assert_eq!(a.v, b.v);
}

#[test]
fn a_restored_memory_continues_bitwise() {
    // Mid-recovery, while the step control has halved the sub-step: an
    // integrator built afresh and given the first one's memory takes the same
    // steps, bit for bit (what checkpoints rely on).
    let (problem, mut state) = compressed_block();
    let opts = ExplicitOptions::default();
    let mut first = Explicit::new(&problem, opts).unwrap();
    let steps = (0.2 / first.dt()).ceil() as usize;
    let mut substeps = Vec::new();
    for k in 0..steps {
        if k == steps / 3 {
            let memory = first.memory();
            assert!(!memory.is_empty());
            let mut resumed_state = state.clone();
            let mut second = Explicit::new(&problem, opts).unwrap();
            second.restore(&memory).unwrap();
            for _ in k..steps {
                first.step(&problem, &mut state).unwrap();
                second.step(&problem, &mut resumed_state).unwrap();
            }
            assert_eq!(state.x, resumed_state.x);
            assert_eq!(state.v, resumed_state.v);
            assert_eq!(state.time.to_bits(), resumed_state.time.to_bits());
            assert_eq!(first.memory(), second.memory());
            break;
        }
        substeps.push(first.step(&problem, &mut state).unwrap().substeps);
    }
    // The memory was taken while the control was at work.
    assert!(substeps.iter().any(|&s| s != substeps[0]), "{substeps:?}");
    // A memory that does not fit is refused, not used.
    let mut other = Explicit::new(&problem, opts).unwrap();
    let mut bad = first.memory();
    bad.counters.pop();
    assert!(other.restore(&bad).is_err());
    let mut bad = first.memory();
    bad.states.clear();
    assert!(other.restore(&bad).is_err());
}
