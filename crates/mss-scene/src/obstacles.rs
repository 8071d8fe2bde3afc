//! `[[obstacles]]`: rigid obstacles the body touches (the library's
//! [`mss_core::contact`]), as scenes write them.
//!
//! ```toml
//! [[obstacles]]
//! shape = { kind = "ground", gap = 0.02 }   # the plane z = (lowest node) - gap
//! friction = 0.5
//!
//! [[obstacles]]
//! shape = { kind = "sphere", centre = [0.1, 0.03, 0.2], radius = 0.03 }
//! motion = [[0.0, 0.0, 0.0, 0.0], [0.5, 0.0, 0.0, -0.02], [1.0, 0.0, 0.0, 0.0]]
//! ```
//!
//! The shape's `kind` is resolved by name in [`Shapes`] (the registry's
//! `shapes`), where a program registers its own ([`ShapeFactory`]; see
//! `examples/custom_obstacle.rs`). Built-in shapes: `plane` (`point`, outward `normal`), `ground` (a plane facing +z
//! at the body's lowest node less `gap`), `sphere` (`centre`, `radius`),
//! `box` (axis-aligned, `min`, `max`), `capsule` (segment `a`, `b`,
//! `radius`), `mesh` (a closed surface file, `path` relative to the scene,
//! placed like `[mesh]`); lengths in metres. `friction` is Coulomb's coefficient (static
//! and kinetic; `friction_kinetic` sets the kinetic one lower), `stiffness`
//! the penalty (N/m) of a node of the mean boundary-node mass (each node's
//! scales with its mass; default: contact at 0.7 of the lattice's highest
//! frequency), `damping_ratio` that of the
//! contact spring (default 0.2), `motion` keyframes `[t, dx, dy, dz]` of the
//! obstacle's offset (s, m), linear in between. `[contact] points` chooses
//! what touches: the lattice's boundary `"nodes"` (default), the embedded
//! `"surface"`'s vertices, or `"both"`.

use mss_core::contact::{
    Capsule, Contact, ContactPoints, ContactSettings, Cuboid, MeshObstacle, Obstacle,
    ObstacleError, Path, Plane, Sphere,
};
use mss_core::{Model, Vec3};
use serde::Deserialize;

use crate::kind_table::{KindKeysError, KindTable};

/// An obstacle's shape as a scene gives it: `kind`, resolved by name in
/// the [`Shapes`] registry when the problem is built, and the table's other
/// keys, which the shape's factory reads ([`KindTable::keys_as`]).
pub type ShapeSpec = KindTable;

impl From<KindKeysError> for ObstacleError {
    fn from(e: KindKeysError) -> Self {
        ObstacleError::Invalid(format!("shape {:?}: {}", e.kind, e.message))
    }
}

/// The built-in shapes, registered in [`Shapes::default`] under their
/// snake-case names.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum BuiltinShape {
    /// The half-space behind the plane through `point` with outward `normal`.
    Plane {
        /// A point of the plane (m).
        point: [f64; 3],
        /// Outward normal (any length).
        normal: [f64; 3],
    },
    /// The plane facing +z at the body's lowest rest node, lowered by `gap` (m).
    Ground {
        /// Distance below the lowest node (m, default 0).
        #[serde(default)]
        gap: f64,
    },
    /// A ball.
    Sphere {
        /// Centre (m).
        centre: [f64; 3],
        /// Radius (m).
        radius: f64,
    },
    /// An axis-aligned box.
    Box {
        /// Minimum corner (m).
        min: [f64; 3],
        /// Maximum corner (m).
        max: [f64; 3],
    },
    /// The solid inside a closed surface mesh (any format `[mesh]` takes),
    /// relative to the scene file's folder and placed like `[mesh]`.
    Mesh {
        /// The mesh file.
        path: String,
    },
    /// The points within `radius` of the segment `a b`.
    Capsule {
        /// One end (m).
        a: [f64; 3],
        /// The other end (m).
        b: [f64; 3],
        /// Radius (m).
        radius: f64,
    },
}

pub use crate::scene::{ContactSection, ObstacleSpec};

fn v(a: [f64; 3]) -> Vec3 {
    Vec3::new(a[0], a[1], a[2])
}

impl ObstacleSpec {
    /// The contact settings of this obstacle for `model`.
    pub fn settings(&self, model: &Model) -> Result<ContactSettings, ObstacleError> {
        let d = ContactSettings::for_model(model);
        let friction = self.friction.unwrap_or(d.friction_static);
        let s = ContactSettings {
            stiffness: self.stiffness.unwrap_or(d.stiffness),
            friction_static: friction,
            friction_kinetic: self.friction_kinetic.unwrap_or(friction),
            damping_ratio: self.damping_ratio.unwrap_or(d.damping_ratio),
        };
        s.validate()?;
        Ok(s)
    }

    /// The obstacle for `model`, its shape resolved in `shapes`; `mesh_of`
    /// loads and places a mesh file the shape names.
    pub fn obstacle(
        &self,
        model: &Model,
        mesh_of: &dyn Fn(&str) -> Result<hexmesh::TriMesh, String>,
        shapes: &Shapes,
    ) -> Result<Box<dyn Obstacle>, ObstacleError> {
        let path = self.path().map_err(|e| ObstacleError::Invalid(e.message))?;
        let context = ShapeContext {
            model,
            mesh_of,
            path,
        };
        let factory = shapes.lookup(&self.shape.kind).map_err(|unknown| {
            ObstacleError::Invalid(format!(
                "unknown shape kind {:?}; known: {}",
                unknown.name, unknown.known
            ))
        })?;
        factory(&self.shape, &context)
    }
}

/// What a shape's factory may use: the model (a `ground` sits below its
/// lowest node), the loader of the scene's meshes (placed like `[mesh]`) and
/// the obstacle's motion, which the factory applies (built-ins through their
/// `moving`, any obstacle through [`mss_core::contact::Moving`]).
pub struct ShapeContext<'a> {
    /// The body's model.
    pub model: &'a Model,
    /// Loads and places a mesh file the scene names.
    pub mesh_of: &'a dyn Fn(&str) -> Result<hexmesh::TriMesh, String>,
    /// The obstacle's `motion`.
    pub path: Path,
}

/// Builds an obstacle from its shape table: one entry of [`Shapes`].
pub type ShapeFactory = std::sync::Arc<
    dyn Fn(&ShapeSpec, &ShapeContext<'_>) -> Result<Box<dyn Obstacle>, ObstacleError> + Send + Sync,
>;

/// The obstacle shapes a scene can name in `shape = { kind = ... }`: the
/// built-ins ([`BuiltinShape`]) and any a program registers.
#[derive(Clone, Debug)]
pub struct Shapes {
    entries: mss_registry::Named<ShapeFactory>,
}

impl Default for Shapes {
    fn default() -> Self {
        let mut shapes = Shapes {
            entries: mss_registry::Named::new(),
        };
        for kind in ["plane", "ground", "sphere", "box", "mesh", "capsule"] {
            shapes.register(kind, std::sync::Arc::new(builtin_obstacle));
        }
        shapes
    }
}

impl Shapes {
    /// Registers (or replaces) the shape called `kind`.
    pub fn register(&mut self, kind: &str, factory: ShapeFactory) {
        self.entries.register(kind, factory);
    }

    /// The registered kinds, in registration order.
    pub fn names(&self) -> Vec<String> {
        self.entries.names()
    }

    fn lookup(&self, kind: &str) -> Result<&ShapeFactory, mss_registry::UnknownName> {
        self.entries.lookup(kind)
    }
}

impl BuiltinShape {
    /// The built-in shape `spec` is, if its kind is one (for a front end
    /// that draws obstacles).
    pub fn of(spec: &ShapeSpec) -> Option<BuiltinShape> {
        spec.tagged_as().ok()
    }
}

fn builtin_obstacle(
    spec: &ShapeSpec,
    context: &ShapeContext<'_>,
) -> Result<Box<dyn Obstacle>, ObstacleError> {
    let shape: BuiltinShape = spec.tagged_as()?;
    let path = context.path.clone();
    Ok(match shape {
        BuiltinShape::Plane { point, normal } => {
            Box::new(Plane::new(v(point), v(normal))?.moving(path))
        }
        BuiltinShape::Ground { gap } => {
            if !gap.is_finite() {
                return Err(ObstacleError::Invalid(format!(
                    "ground gap {gap} must be finite"
                )));
            }
            let lowest = context
                .model
                .rest_positions()
                .iter()
                .map(|p| p.z)
                .fold(f64::INFINITY, f64::min);
            Box::new(Plane::new(Vec3::new(0.0, 0.0, lowest - gap), Vec3::z())?.moving(path))
        }
        BuiltinShape::Sphere { centre, radius } => {
            Box::new(Sphere::new(v(centre), radius)?.moving(path))
        }
        BuiltinShape::Box { min, max } => Box::new(Cuboid::new(v(min), v(max))?.moving(path)),
        BuiltinShape::Mesh { path: file } => {
            let mesh = (context.mesh_of)(&file).map_err(ObstacleError::Invalid)?;
            Box::new(MeshObstacle::new(&mesh)?.moving(path))
        }
        BuiltinShape::Capsule { a, b, radius } => {
            Box::new(Capsule::new(v(a), v(b), radius)?.moving(path))
        }
    })
}

/// The contact of `model` with `specs`, or the first bad obstacle (0-based)
/// and why.
pub fn build_contact(
    model: &Model,
    specs: &[ObstacleSpec],
    mesh_of: &dyn Fn(&str) -> Result<hexmesh::TriMesh, String>,
    points: ContactPoints,
    surface: Option<&hexmesh::Embedding>,
) -> Result<Option<Contact>, (usize, ObstacleError)> {
    build_contact_with(
        model,
        specs,
        &Shapes::default(),
        Vec::new(),
        mesh_of,
        points,
        surface,
    )
}

/// [`build_contact`] with `extra` obstacles after the scene's (an
/// interactive front end's tools: a poking sphere, a cursor); a contact is
/// built when either list is non-empty.
pub fn build_contact_with(
    model: &Model,
    specs: &[ObstacleSpec],
    shapes: &Shapes,
    extra: Vec<(Box<dyn Obstacle>, ContactSettings)>,
    mesh_of: &dyn Fn(&str) -> Result<hexmesh::TriMesh, String>,
    points: ContactPoints,
    surface: Option<&hexmesh::Embedding>,
) -> Result<Option<Contact>, (usize, ObstacleError)> {
    if specs.is_empty() && extra.is_empty() {
        return Ok(None);
    }
    let mut obstacles = Vec::with_capacity(specs.len() + extra.len());
    for (i, spec) in specs.iter().enumerate() {
        let o = spec.obstacle(model, mesh_of, shapes).map_err(|e| (i, e))?;
        let s = spec.settings(model).map_err(|e| (i, e))?;
        obstacles.push((o, s));
    }
    obstacles.extend(extra);
    Ok(Some(Contact::with_points(
        model, obstacles, points, surface,
    )))
}
