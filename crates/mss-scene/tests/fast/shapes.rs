//! Obstacle shapes are resolved by name in the registry: a shape a program
//! registers is used like a built-in one (here a ball that wraps the
//! library's sphere gives bitwise the built-in sphere's run), and unknown
//! kinds or bad keys are refused naming the obstacle.

use std::sync::Arc;

use mss_scene::mss_core::Vec3;
use mss_scene::mss_core::contact::{Moving, Obstacle, ObstacleError, Sphere};
use mss_scene::obstacles::{ShapeContext, ShapeSpec};
use mss_scene::{Cancel, Job, JobError, Registry, SceneInput, no_progress};

fn scene(shape: &str) -> String {
    format!(
        "[mesh]\npath = \"builtin:critter\"\n[voxelize]\ncells = 6\n[material]\n\
         young = 1.0e5\npoisson = 0.3\ndensity = 1000.0\n[loads]\n\
         gravity = [0.0, 0.0, -9.81]\n[solver]\nduration = 0.02\n[output]\nevery_time = 0.01\n\
         [[obstacles]]\nshape = {shape}\n"
    )
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct BallKeys {
    centre: [f64; 3],
    radius: f64,
}

fn ball(spec: &ShapeSpec, context: &ShapeContext<'_>) -> Result<Box<dyn Obstacle>, ObstacleError> {
    let k: BallKeys = spec.keys_as()?;
    let sphere = Sphere::new(Vec3::new(k.centre[0], k.centre[1], k.centre[2]), k.radius)?;
    Ok(Box::new(Moving::new(
        Box::new(sphere),
        context.path.clone(),
    )))
}

fn run(shape: &str, registry: Registry) -> Vec<u8> {
    let input = SceneInput::from_toml(&scene(shape), "shapes.toml").unwrap();
    let job = Job::prepare(input, registry, &no_progress).unwrap();
    let dir = tempfile::tempdir().unwrap();
    job.run(dir.path(), &no_progress, &Cancel::new()).unwrap();
    std::fs::read(dir.path().join("lattice_0002.vtu")).unwrap()
}

#[test]
fn a_registered_shape_is_used_by_name() {
    // A ball under the body's lowest part: it pushes the body up.
    let keys = "centre = [0.0, 0.0, -0.02], radius = 0.05";
    let builtin = run(
        &format!("{{ kind = \"sphere\", {keys} }}"),
        Registry::default(),
    );
    let mut registry = Registry::default();
    registry.shapes.register("ball", Arc::new(ball));
    let custom = run(&format!("{{ kind = \"ball\", {keys} }}"), registry);
    assert!(
        builtin == custom,
        "the registered ball differs from the built-in sphere"
    );
    let free = run(
        "{ kind = \"sphere\", centre = [9.0, 9.0, 9.0], radius = 0.01 }",
        Registry::default(),
    );
    assert!(
        free != builtin,
        "the ball does not touch the body: the test shows nothing"
    );
}

#[test]
fn unknown_kinds_and_bad_keys_name_the_obstacle() {
    let prepare = |shape: &str| {
        let input = SceneInput::from_toml(&scene(shape), "shapes.toml").unwrap();
        Job::prepare(input, Registry::default(), &no_progress).unwrap_err()
    };
    for (shape, words) in [
        (
            "{ kind = \"cone\", radius = 1.0 }",
            "unknown shape kind \"cone\"; known: plane, ground, sphere, box, mesh, capsule",
        ),
        ("{ kind = \"sphere\", centre = [0.0, 0.0, 0.0] }", "radius"),
        (
            "{ kind = \"sphere\", centre = [0.0, 0.0, 0.0], radius = 1.0, colour = 2 }",
            "colour",
        ),
    ] {
        let err = prepare(shape);
        assert!(matches!(err, JobError::Setting { .. }), "{err}");
        let text = err.to_string();
        assert!(text.contains("[[obstacles]] #1"), "{text}");
        assert!(text.contains(words), "{text}");
    }
    let err = SceneInput::from_toml(&scene("{ radius = 1.0 }"), "shapes.toml").unwrap_err();
    assert!(err.to_string().contains("kind"), "{err}");
}
