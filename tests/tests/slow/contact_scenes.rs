//! The bundled contact scenes: the critter dropped onto the ground lands,
//! bounces and settles on it; a sphere pressed into its back leaves it
//! where it was once withdrawn. Stepped exactly as `mss run` does.

use mss_core::{State, Vec3};
use mss_scene::{Job, Registry, SceneInput, no_progress};

const DROP: &str = include_str!("../../../data/scenes/drop.toml");
const PRESS: &str = include_str!("../../../data/scenes/press.toml");

/// Steps a bundled scene (its mesh from the crate), calling `each` after
/// every step.
fn run(toml: &str, mut each: impl FnMut(&Job, &State)) -> (Job, State) {
    let text = toml.replace(
        "path = \"../meshes/critter.obj\"",
        "path = \"builtin:critter\"",
    );
    let input = SceneInput::from_toml(&text, "scene.toml").unwrap();
    let job = Job::prepare(input, Registry::default(), &no_progress).unwrap();
    let mut state = State::at_rest(job.problem.model());
    job.problem.apply_constraints(&mut state);
    let mut integrator = job
        .input
        .integrator(&job.registry, &job.problem, &job.plan)
        .unwrap()
        .unwrap();
    for _ in 0..job.plan.steps {
        integrator.step(&job.problem, &mut state).unwrap();
        each(&job, &state);
    }
    (job, state)
}

fn centre_z(job: &Job, s: &State) -> f64 {
    let m = job.problem.model();
    s.x.iter()
        .zip(m.masses())
        .map(|(x, mi)| x.z * mi)
        .sum::<f64>()
        / m.total_mass()
}

#[test]
fn the_dropped_critter_lands_bounces_and_settles() {
    let mut lowest = f64::INFINITY;
    let mut heights = Vec::new();
    let (job, s) = run(DROP, |job, s| {
        lowest = lowest.min(s.x.iter().map(|x| x.z).fold(f64::INFINITY, f64::min));
        heights.push(centre_z(job, s));
    });
    let model = job.problem.model();
    let ground = model
        .rest_positions()
        .iter()
        .map(|p| p.z)
        .fold(f64::INFINITY, f64::min)
        - 0.02;
    // It fell 2 cm, and came back up at least once (a bounce).
    let start = heights[0];
    let bottom = heights.iter().cloned().fold(f64::INFINITY, f64::min);
    assert!(start - bottom > 0.019, "fell {} m", start - bottom);
    let k_bottom = heights.iter().position(|&h| h == bottom).unwrap();
    let rebound = heights[k_bottom..].iter().cloned().fold(f64::MIN, f64::max);
    assert!(rebound > bottom + 1e-4, "no bounce: {bottom} .. {rebound}");
    // No node ever went deeper into the ground than a fifth of a cell, even
    // at the impact (a penalty lets a node in by about its speed over the
    // contact frequency: 0.6 m/s here).
    assert!(
        lowest > ground - 0.2 * model.h(),
        "{lowest} vs the ground at {ground}"
    );
    // At the end it rests: carried by the ground, nearly still.
    let weight = model.total_mass() * 9.81;
    let support: Vec3 = job.problem.contact_forces(&s).iter().sum();
    assert!(
        (support.z - weight).abs() < 0.05 * weight,
        "{} vs {weight}",
        support.z
    );
    let speed = s.v.iter().map(|v| v.norm()).fold(0.0, f64::max);
    assert!(speed < 0.01, "still moving at {speed} m/s");
    assert!(model.inverted_cells(&s.x).is_empty());
}

#[test]
fn the_pressed_critter_recovers_when_the_sphere_withdraws() {
    let mut deepest = 0.0f64;
    let mut pushed = 0.0f64;
    let (job, s) = run(PRESS, |job, s| {
        let f: Vec3 = job.problem.contact_forces(s).iter().sum();
        pushed = pushed.max(-f.z);
        if let Some(c) = job.problem.contact() {
            for (o, _) in c.obstacles() {
                for x in &s.x {
                    if let Some(p) = o.penetration(s.time, *x) {
                        deepest = deepest.max(p.depth);
                    }
                }
            }
        }
    });
    let model = job.problem.model();
    assert!(pushed > 0.1, "the sphere pushed with {pushed} N at most");
    assert!(
        deepest < 0.2 * model.h(),
        "a node {deepest} m inside the sphere"
    );
    // Withdrawn, the back is back where gravity alone holds it: no contact.
    let f: Vec3 = job.problem.contact_forces(&s).iter().sum();
    assert_eq!(f, Vec3::zeros());
    assert!(model.inverted_cells(&s.x).is_empty());
}

/// With `[contact] points = "both"` the rendered surface, not only the
/// lattice, keeps the obstacle out: the embedded critter's back, which lies
/// outside its lattice's nodes in places, no longer lets the sphere in.
#[test]
fn the_embedded_surface_can_touch_too() {
    let deepest_surface = |points: &str| {
        let scene = PRESS
            .replace(
                "[[obstacles]]",
                &format!("[contact]\npoints = \"{points}\"\n\n[[obstacles]]"),
            )
            .replace("duration = 1.0        # s", "duration = 0.5        # s");
        let mut deepest = 0.0f64;
        let mut embedding = None;
        let (job, _) = run(&scene, |job, s| {
            let e =
                embedding.get_or_insert_with(|| hexmesh::Embedding::new(job.lattice(), job.mesh()));
            let nodes: Vec<[f64; 3]> = s.x.iter().map(|p| [p.x, p.y, p.z]).collect();
            let (o, _) = job.problem.contact().unwrap().obstacles().next().unwrap();
            for v in e.deform(&nodes) {
                if let Some(p) = o.penetration(s.time, Vec3::new(v[0], v[1], v[2])) {
                    deepest = deepest.max(p.depth);
                }
            }
        });
        (deepest, job.problem.model().h())
    };
    let (nodes, h) = deepest_surface("nodes");
    let (both, _) = deepest_surface("both");
    assert!(
        nodes > 0.1 * h,
        "with nodes only the sphere enters the surface by {nodes}"
    );
    assert!(
        both < 0.6 * nodes && both < 0.2 * h,
        "{both} vs {nodes} (h {h})"
    );
}
