//! A program registers an obstacle shape of its own, a vertical cylinder
//! (a post, a tool shaft), and a scene names it like a built-in one:
//!
//! ```toml
//! [[obstacles]]
//! shape = { kind = "post", centre = [0.0, 0.0], radius = 0.02 }
//! ```
//!
//!     cargo run --release -p mss-scene --example custom_obstacle
//!
//! The critter falls onto the ground beside a post pushed into its side;
//! the run reports the contact and the body's largest displacement.

use std::sync::Arc;

use mss_scene::mss_core::contact::{Moving, Obstacle, ObstacleError, Penetration};
use mss_scene::mss_core::{Mat3, Vec3};
use mss_scene::obstacles::{ShapeContext, ShapeSpec};
use mss_scene::{Cancel, Job, Registry, SceneInput, no_progress};
use serde::Deserialize;

/// The infinite vertical cylinder of `radius` around the line through
/// `centre` (x, y) parallel to z.
#[derive(Debug)]
struct Post {
    centre: [f64; 2],
    radius: f64,
}

impl Obstacle for Post {
    fn name(&self) -> String {
        format!("post of radius {} m", self.radius)
    }

    fn penetration(&self, _t: f64, p: Vec3) -> Option<Penetration> {
        let d = Vec3::new(p.x - self.centre[0], p.y - self.centre[1], 0.0);
        let r = d.norm();
        if r >= self.radius || r == 0.0 {
            return None;
        }
        let normal = d / r;
        // The normal turns with the point around the axis only.
        let across = Mat3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0);
        Some(Penetration {
            depth: self.radius - r,
            normal,
            normal_gradient: (across - normal * normal.transpose()) / r,
        })
    }
}

/// The keys of `shape = { kind = "post", ... }`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PostKeys {
    centre: [f64; 2],
    radius: f64,
}

fn post(spec: &ShapeSpec, context: &ShapeContext<'_>) -> Result<Box<dyn Obstacle>, ObstacleError> {
    let keys: PostKeys = spec.keys_as()?;
    let finite = keys.radius.is_finite() && keys.centre.iter().all(|c| c.is_finite());
    if !(finite && keys.radius > 0.0) {
        return Err(ObstacleError::Invalid(format!(
            "post radius {} and centre {:?} must be finite, the radius positive",
            keys.radius, keys.centre
        )));
    }
    let post = Post {
        centre: keys.centre,
        radius: keys.radius,
    };
    Ok(Box::new(Moving::new(Box::new(post), context.path.clone())))
}

const SCENE: &str = r#"
[mesh]
path = "builtin:critter"
[voxelize]
cells = 10
[material]
young = 2.0e4
poisson = 0.3
density = 1000.0
[loads]
gravity = [0.0, 0.0, -9.81]
[solver]
duration = 0.2
damping = 5.0
[output]
every_time = 0.1
skin_obj = false
embedded = false

[[obstacles]]
shape = { kind = "ground" }

[[obstacles]]
shape = { kind = "post", centre = [-0.06, 0.0], radius = 0.02 }
motion = [[0.0, 0.0, 0.0, 0.0], [0.2, 0.03, 0.0, 0.0]]
"#;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut registry = Registry::default();
    registry.shapes.register("post", Arc::new(post));
    assert!(registry.shapes.names().contains(&"post".to_owned()));

    let input = SceneInput::from_toml(SCENE, "post.toml")?;
    let job = Job::prepare(input, registry, &no_progress)?;
    let contact = job.problem.contact().expect("the scene has obstacles");
    let names: Vec<String> = contact.obstacles().map(|(o, _)| o.name()).collect();
    println!("obstacles: {names:?}");
    assert!(names[1].contains("post"));
    let out = std::env::temp_dir().join("mss-custom-obstacle");
    let summary = job.run(&out, &no_progress, &Cancel::new())?;
    println!(
        "{} steps, largest displacement {:.4} m, frames in {}",
        summary.steps,
        summary.max_displacement,
        out.display()
    );
    Ok(())
}
