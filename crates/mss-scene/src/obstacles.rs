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

/// An obstacle's shape as a scene gives it: `kind`, resolved by name in
/// the [`Shapes`] registry when the problem is built, and the table's other
/// keys, which the shape's factory reads ([`ShapeSpec::keys_as`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ShapeSpec {
    /// The shape's name in [`Shapes`] (`"plane"`, `"sphere"`, ...).
    pub kind: String,
    /// The other keys of the `shape = { ... }` table.
    pub keys: toml::Table,
}

impl<'de> Deserialize<'de> for ShapeSpec {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let mut keys = toml::Table::deserialize(d)?;
        match keys.remove("kind") {
            Some(toml::Value::String(kind)) => Ok(ShapeSpec { kind, keys }),
            Some(other) => Err(serde::de::Error::custom(format!(
                "kind = {other}: the shape's kind is a name (\"sphere\", ...)"
            ))),
            None => Err(serde::de::Error::missing_field("kind")),
        }
    }
}

impl ShapeSpec {
    /// The keys read as `T` (a factory's own table type, usually with
    /// `deny_unknown_fields`), with serde's message on a bad key.
    pub fn keys_as<T: serde::de::DeserializeOwned>(&self) -> Result<T, ObstacleError> {
        toml::Value::Table(self.keys.clone())
            .try_into()
            .map_err(|e: toml::de::Error| {
                ObstacleError::Invalid(format!("shape {:?}: {}", self.kind, e.message().trim()))
            })
    }

    /// The built-in shape this is, if its kind is one (for a front end that
    /// draws obstacles).
    pub fn builtin(&self) -> Option<BuiltinShape> {
        self.read_builtin().ok()
    }

    fn read_builtin(&self) -> Result<BuiltinShape, ObstacleError> {
        let mut table = self.keys.clone();
        table.insert("kind".into(), toml::Value::String(self.kind.clone()));
        toml::Value::Table(table)
            .try_into()
            .map_err(|e: toml::de::Error| {
                ObstacleError::Invalid(format!("shape {:?}: {}", self.kind, e.message().trim()))
            })
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

/// `[contact]`: which points touch the obstacles.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct ContactSection {
    /// `"nodes"` (the lattice's boundary nodes, default), `"surface"` (the
    /// embedded input surface's vertices, what is rendered) or `"both"`.
    #[serde(default)]
    pub points: PointsKey,
}

/// `[contact] points`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum PointsKey {
    /// The lattice's boundary nodes.
    #[default]
    Nodes,
    /// The embedded surface's vertices.
    Surface,
    /// Both.
    Both,
}

impl PointsKey {
    /// The library's choice.
    pub fn points(self) -> ContactPoints {
        match self {
            PointsKey::Nodes => ContactPoints::Nodes,
            PointsKey::Surface => ContactPoints::Surface,
            PointsKey::Both => ContactPoints::Both,
        }
    }
}

/// One `[[obstacles]]` table.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObstacleSpec {
    /// The shape.
    pub shape: ShapeSpec,
    /// Coulomb friction coefficient (default 0.5).
    pub friction: Option<f64>,
    /// Kinetic friction coefficient (default: `friction`).
    pub friction_kinetic: Option<f64>,
    /// Penalty stiffness (N/m) of a node of the mean boundary-node mass
    /// (default: see [`ContactSettings::for_model`]).
    pub stiffness: Option<f64>,
    /// Damping ratio of the contact spring (default 0.2).
    pub damping_ratio: Option<f64>,
    /// Keyframes `[t, dx, dy, dz]` of the obstacle's offset (s, m).
    #[serde(default)]
    pub motion: Vec<[f64; 4]>,
}

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
        let path = Path::new(
            self.motion
                .iter()
                .map(|k| (k[0], Vec3::new(k[1], k[2], k[3])))
                .collect(),
        )
        .ok_or_else(|| {
            ObstacleError::Invalid(
                "motion keyframes [t, dx, dy, dz] must be finite with increasing times".into(),
            )
        })?;
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

fn builtin_obstacle(
    spec: &ShapeSpec,
    context: &ShapeContext<'_>,
) -> Result<Box<dyn Obstacle>, ObstacleError> {
    let mut table = spec.keys.clone();
    table.insert("kind".into(), toml::Value::String(spec.kind.clone()));
    let shape: BuiltinShape =
        toml::Value::Table(table)
            .try_into()
            .map_err(|e: toml::de::Error| {
                ObstacleError::Invalid(format!("shape {:?}: {}", spec.kind, e.message().trim()))
            })?;
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
