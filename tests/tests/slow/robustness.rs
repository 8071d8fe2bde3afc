//! The robustness suite (docs/robustness.md): soft bodies under gravity run
//! to the end with the default model, without inverted cells, and without
//! the lattice's zigzag. Each scene is stepped exactly as `mss run` does
//! (the scene's integrator, time plan and checks).

use mss_core::State;
use mss_scene::{Job, Registry, SceneInput, no_progress};

const DEFAULT_SCENE: &str = include_str!("../../../data/scenes/default.toml");
const TEMPLATE_SCENE: &str = include_str!("../../../data/scenes/template.toml");

/// The default scene with the bundled mesh and another Young's modulus.
fn critter(young: f64) -> String {
    let (mesh, modulus) = ("path = \"../meshes/critter.obj\"", "young = 1.0e5");
    assert!(DEFAULT_SCENE.contains(mesh) && DEFAULT_SCENE.contains(modulus));
    DEFAULT_SCENE
        .replace(mesh, "path = \"builtin:critter\"")
        .replace(modulus, &format!("young = {young:e}"))
}

/// Steps a scene to its end; the final state, or the solver's message.
fn run_to_end(toml: &str) -> Result<(Job, State), String> {
    let input = SceneInput::from_toml(toml, "suite.toml").map_err(|e| e.to_string())?;
    let job = Job::prepare(input, Registry::default(), &no_progress).map_err(|e| e.to_string())?;
    let mut state = State::at_rest(job.problem.model());
    job.problem.apply_constraints(&mut state);
    let mut integrator = job
        .input
        .integrator(&job.registry, &job.problem, &job.plan)
        .map_err(|e| e.to_string())?
        .expect("a time-stepping scene");
    for _ in 0..job.plan.steps {
        integrator
            .step(&job.problem, &mut state)
            .map_err(|e| e.to_string())?;
    }
    Ok((job, state))
}

fn worst_deviation(job: &Job, state: &State) -> f64 {
    job.problem
        .model()
        .affine_deviation(&state.x)
        .into_iter()
        .fold(0.0, f64::max)
}

#[test]
fn the_default_job_sags_without_zigzag() {
    let (job, state) = run_to_end(&critter(1.0e5)).unwrap();
    assert!(job.problem.model().inverted_cells(&state.x).is_empty());
    let dev = worst_deviation(&job, &state);
    assert!(
        dev <= 0.02,
        "worst cell deviation from affine {:.2} % of h",
        100.0 * dev
    );
    // It did sag, and settled: the default damping is meant to.
    let sag = state
        .displacements(job.problem.model())
        .iter()
        .map(|u| u.norm())
        .fold(0.0, f64::max);
    assert!(sag > 1e-3, "max displacement {sag}");
    assert!(state.kinetic_energy(job.problem.model().masses()) < 1e-6);
}

#[test]
fn the_template_at_20_kpa_runs_to_the_end() {
    // The template's comment names 20 kPa as too soft to carry the weight
    // (it shipped with it before): the default model still runs it.
    let soft = TEMPLATE_SCENE.replace("young = 1.0e5", "young = 2.0e4");
    assert_ne!(soft, TEMPLATE_SCENE);
    let (job, state) = run_to_end(&soft).unwrap();
    let model = job.problem.model();
    assert!(model.inverted_cells(&state.x).is_empty());
    // E = 20 kPa: at the edge of buckling under its own weight (the refined
    // FEM's equilibrium path ends at 0.90 g); it sags by centimetres.
    let umax = state
        .displacements(model)
        .iter()
        .map(|u| u.norm())
        .fold(0.0, f64::max);
    assert!(umax > 0.01 && umax < 0.1, "max displacement {umax}");
}

#[test]
fn a_soft_critter_runs_to_the_end_with_the_default_model() {
    let (job, state) = run_to_end(&critter(2.0e4)).unwrap();
    assert!(job.problem.model().inverted_cells(&state.x).is_empty());
    assert!(worst_deviation(&job, &state) < 0.2);
}

#[test]
fn the_papers_model_is_refused_statically_where_its_lattice_folds() {
    // Without hourglass control the default critter's equilibrium under
    // gravity is unstable (docs/robustness.md); the static solver says so.
    let toml = critter(1.0e5)
        .replace(
            "parameterization = \"volumetric-barrier+hg\"\nhourglass = 1.0",
            "parameterization = \"paper\"",
        )
        .replace("kind = \"explicit\"", "kind = \"static\"");
    assert!(toml.contains("\"paper\""));
    let input = SceneInput::from_toml(&toml, "suite.toml").unwrap();
    let job = Job::prepare(input, Registry::default(), &no_progress).unwrap();
    let out = tempfile::tempdir().unwrap();
    let err = job
        .run(out.path(), &no_progress, &mss_scene::Cancel::new())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("unstable") && err.contains("accept_unstable"),
        "{err}"
    );
    let accepted = toml.replace(
        "kind = \"static\"",
        "kind = \"static\"\naccept_unstable = true",
    );
    let input = SceneInput::from_toml(&accepted, "suite.toml").unwrap();
    let job = Job::prepare(input, Registry::default(), &no_progress).unwrap();
    job.run(out.path(), &no_progress, &mss_scene::Cancel::new())
        .unwrap();
}

#[test]
fn a_critter_twice_past_its_buckling_load_folds_without_blowing_up() {
    // E = 10 kPa: the body cannot carry its weight (docs/robustness.md) and
    // collapses; the explicit step's control follows its stiffening.
    let (job, state) = run_to_end(&critter(1.0e4)).unwrap();
    assert!(job.problem.model().inverted_cells(&state.x).is_empty());
}

#[test]
fn the_soft_stanford_bunny_runs_to_the_end() {
    // 0.15 m, 32 cells, E = 10 kPa, nu = 0.45, the lowest layer held (a few
    // cells carry the whole weight, compressed hard): the barrier stiffens
    // them and the explicit step follows.
    // The committed bunny is Y up and 9.657897 units tall: the scene turns
    // and scales it.
    let mesh = concat!(env!("CARGO_MANIFEST_DIR"), "/../data/meshes/bunny.obj");
    let toml = critter(1.0e4)
        .replace(
            "path = \"builtin:critter\"",
            &format!("path = {mesh:?}\nup = \"y\"\nscale = {}", 0.15 / 9.657897),
        )
        .replace("cells = 24", "cells = 32")
        .replace("poisson = 0.3", "poisson = 0.45")
        .replace("duration = 1.0", "duration = 0.5");
    for key in [
        "cells = 32",
        "poisson = 0.45",
        "duration = 0.5",
        "bunny.obj",
        "up = \"y\"",
    ] {
        assert!(toml.contains(key), "{key}");
    }
    let (job, state) = run_to_end(&toml).unwrap();
    let extent = job.mesh().bounding_box().unwrap().extent();
    assert!((extent[2] - 0.15).abs() < 1e-6, "{extent:?}");
    assert!(job.problem.model().inverted_cells(&state.x).is_empty());
}
