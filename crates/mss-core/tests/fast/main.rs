//! The quick tests of this crate, in one binary (a module per file): `cargo
//! test --release --test fast` runs them, and `cargo fast` runs every crate's
//! (see README).

mod barrier;
mod bodies;
mod contact;
mod determinism;
mod hourglass;
mod model_facts;
mod plane;
mod rigid_cell_modes;
mod solvers;
mod step_control;

/// Runs `f` in a rayon pool of `threads` threads: the determinism tests
/// compare runs on several thread counts.
pub fn on_threads<R: Send>(threads: usize, f: impl FnOnce() -> R + Send) -> R {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

/// Steps `p` implicitly `before` times, then an integrator made afresh and
/// given the first one's memory, the first one, and one made afresh without
/// it, `after` times each from there: the restored one is bitwise the first
/// (what checkpoints rely on), the forgetful one is not (so the memory
/// carries what the steps depend on, and the test can tell). Returns the
/// memory.
pub fn assert_restored_implicit_continues_bitwise(
    p: &mss_core::solver::Problem,
    opts: mss_core::solver::ImplicitOptions,
    before: usize,
    after: usize,
) -> mss_core::solver::IntegratorMemory {
    use mss_core::solver::{Implicit, Integrator, State};
    let mut first = Implicit::new(p, opts).unwrap();
    let mut s = State::at_rest(p.model());
    for _ in 0..before {
        first.step(p, &mut s).unwrap();
    }
    let memory = first.memory();
    let mut restored = Implicit::new(p, opts).unwrap();
    restored.restore(&memory).unwrap();
    let mut forgetful = Implicit::new(p, opts).unwrap();
    let (mut s2, mut s3) = (s.clone(), s.clone());
    for _ in 0..after {
        first.step(p, &mut s).unwrap();
        restored.step(p, &mut s2).unwrap();
        forgetful.step(p, &mut s3).unwrap();
    }
    assert_eq!(s.x, s2.x);
    assert_eq!(s.v, s2.v);
    assert_eq!(first.memory(), restored.memory());
    assert_ne!(s.x, s3.x, "a fresh linear solver gives the same bits");
    // A memory that is not the implicit integrator's is refused.
    let mut bad = memory.clone();
    bad.counters.push(0);
    assert!(Implicit::new(p, opts).unwrap().restore(&bad).is_err());
    let mut bad = memory.clone();
    bad.values.push(0.0);
    assert!(Implicit::new(p, opts).unwrap().restore(&bad).is_err());
    // Values that fit the records but not the problem are not used: the
    // steps go on as a fresh integrator's.
    let mut odd = memory.clone();
    odd.values.iter_mut().for_each(|v| *v = f64::NAN);
    let mut it = Implicit::new(p, opts).unwrap();
    it.restore(&odd).unwrap();
    let mut s4 = s3.clone();
    it.step(p, &mut s4).unwrap();
    assert!(s4.x.iter().all(|x| x.iter().all(|c| c.is_finite())));
    memory
}
