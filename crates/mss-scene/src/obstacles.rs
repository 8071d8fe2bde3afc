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
//! Shapes: `plane` (`point`, outward `normal`), `ground` (a plane facing +z
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

/// An obstacle's shape.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum ShapeSpec {
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

    /// The obstacle for `model` (a `ground` sits below its lowest node);
    /// `mesh_of` loads and places a `mesh` shape's file.
    pub fn obstacle(
        &self,
        model: &Model,
        mesh_of: &dyn Fn(&str) -> Result<hexmesh::TriMesh, String>,
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
        Ok(match &self.shape {
            ShapeSpec::Plane { point, normal } => {
                Box::new(Plane::new(v(*point), v(*normal))?.moving(path))
            }
            ShapeSpec::Ground { gap } => {
                if !gap.is_finite() {
                    return Err(ObstacleError::Invalid(format!(
                        "ground gap {gap} must be finite"
                    )));
                }
                let lowest = model
                    .rest_positions()
                    .iter()
                    .map(|p| p.z)
                    .fold(f64::INFINITY, f64::min);
                Box::new(Plane::new(Vec3::new(0.0, 0.0, lowest - gap), Vec3::z())?.moving(path))
            }
            ShapeSpec::Sphere { centre, radius } => {
                Box::new(Sphere::new(v(*centre), *radius)?.moving(path))
            }
            ShapeSpec::Box { min, max } => Box::new(Cuboid::new(v(*min), v(*max))?.moving(path)),
            ShapeSpec::Mesh { path: file } => {
                let mesh = mesh_of(file).map_err(ObstacleError::Invalid)?;
                Box::new(MeshObstacle::new(&mesh)?.moving(path))
            }
            ShapeSpec::Capsule { a, b, radius } => {
                Box::new(Capsule::new(v(*a), v(*b), *radius)?.moving(path))
            }
        })
    }
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
    build_contact_with(model, specs, Vec::new(), mesh_of, points, surface)
}

/// [`build_contact`] with `extra` obstacles after the scene's (an
/// interactive front end's tools: a poking sphere, a cursor); a contact is
/// built when either list is non-empty.
pub fn build_contact_with(
    model: &Model,
    specs: &[ObstacleSpec],
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
        let o = spec.obstacle(model, mesh_of).map_err(|e| (i, e))?;
        let s = spec.settings(model).map_err(|e| (i, e))?;
        obstacles.push((o, s));
    }
    obstacles.extend(extra);
    Ok(Some(Contact::with_points(
        model, obstacles, points, surface,
    )))
}
