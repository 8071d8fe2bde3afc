//! `[[obstacles]]` and `[contact]`: the rigid obstacles a body touches and
//! which of its points touch them, as tables; building them into the
//! library's contact is [`crate::obstacles`]'s.

use mss_core::Vec3;
use mss_core::contact::{ContactPoints, Path};
use serde::Deserialize;

use super::key::KeyError;
use crate::kind_table::KindTable;

/// `[contact]`: which points touch the obstacles, and the contact between
/// bodies (`[[bodies]]`, or a body with itself).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct ContactSection {
    /// `"nodes"` (the lattice's boundary nodes, default), `"surface"` (the
    /// embedded input surface's vertices, what is rendered) or `"both"`
    /// touch the obstacles. With `"surface"` or `"both"` the bodies also
    /// touch each other (and themselves) through their embedded surfaces,
    /// each one's vertices against the others' triangles, where they are
    /// drawn; with `"nodes"` through their lattices' boundaries.
    #[serde(default)]
    pub points: ContactPoints,
    /// Whether the body of a scene without `[[bodies]]` touches itself
    /// (each of `[[bodies]]` says so in its own table; default false).
    #[serde(default)]
    pub self_contact: bool,
    /// Coulomb friction between bodies (default 0.5).
    pub friction: Option<f64>,
    /// Kinetic friction between bodies (default: `friction`).
    pub friction_kinetic: Option<f64>,
    /// Penalty stiffness between bodies (N/m) of a node of the mean
    /// boundary-node mass (default:
    /// `mss_core::contact::ContactSettings::for_bodies`).
    pub stiffness: Option<f64>,
    /// Damping ratio of the contact spring between bodies (default 0.2).
    pub damping_ratio: Option<f64>,
}

impl ContactSection {
    /// Checks the values given (the library checks them again, with its
    /// defaults, when the contact is built).
    pub fn check(&self) -> Result<(), KeyError> {
        for (key, value) in [
            ("friction", self.friction),
            ("friction_kinetic", self.friction_kinetic),
            ("damping_ratio", self.damping_ratio),
        ] {
            if let Some(v) = value
                && !(v.is_finite() && v >= 0.0)
            {
                return Err(KeyError::new(key, format!("= {v}; must be a number >= 0")));
            }
        }
        if let Some(k) = self.stiffness
            && !(k.is_finite() && k > 0.0)
        {
            return Err(KeyError::new(
                "stiffness",
                format!("= {k}; must be a positive number (N/m)"),
            ));
        }
        if let (Some(mu_s), Some(mu_k)) = (self.friction, self.friction_kinetic)
            && mu_k > mu_s
        {
            return Err(KeyError::new(
                "friction_kinetic",
                format!("= {mu_k}; must not exceed friction = {mu_s}"),
            ));
        }
        Ok(())
    }

    /// The contact settings between bodies: the values given, the rest from
    /// `defaults`.
    pub fn body_settings(
        &self,
        defaults: mss_core::contact::ContactSettings,
    ) -> mss_core::contact::ContactSettings {
        let friction_static = self.friction.unwrap_or(defaults.friction_static);
        mss_core::contact::ContactSettings {
            stiffness: self.stiffness.unwrap_or(defaults.stiffness),
            friction_static,
            friction_kinetic: self.friction_kinetic.unwrap_or(friction_static),
            damping_ratio: self.damping_ratio.unwrap_or(defaults.damping_ratio),
        }
    }
}

/// One `[[obstacles]]` table.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObstacleSpec {
    /// The shape.
    pub shape: KindTable,
    /// Coulomb friction coefficient (default 0.5).
    pub friction: Option<f64>,
    /// Kinetic friction coefficient (default: `friction`).
    pub friction_kinetic: Option<f64>,
    /// Penalty stiffness (N/m) of a node of the mean boundary-node mass
    /// (default: see `mss_core::contact::ContactSettings::for_model`).
    pub stiffness: Option<f64>,
    /// Damping ratio of the contact spring (default 0.2).
    pub damping_ratio: Option<f64>,
    /// Keyframes `[t, dx, dy, dz]` of the obstacle's offset (s, m).
    #[serde(default)]
    pub motion: Vec<[f64; 4]>,
}

impl ObstacleSpec {
    /// Checks what needs no model: the keyframes `[t, dx, dy, dz]` are
    /// finite with increasing times. Friction, stiffness and damping are
    /// checked by the library's `ContactSettings::validate` once the
    /// model's defaults fill what the table leaves out, and the shape's
    /// keys by its factory, both when the problem is built.
    pub fn check(&self) -> Result<(), KeyError> {
        self.path().map(|_| ())
    }

    /// The obstacle's motion: its keyframes as a path, or the key error
    /// saying why they are not one.
    pub fn path(&self) -> Result<Path, KeyError> {
        Path::new(
            self.motion
                .iter()
                .map(|k| (k[0], Vec3::new(k[1], k[2], k[3])))
                .collect(),
        )
        .ok_or_else(|| {
            KeyError::new(
                "motion",
                "keyframes [t, dx, dy, dz] must be finite with increasing times",
            )
        })
    }
}
