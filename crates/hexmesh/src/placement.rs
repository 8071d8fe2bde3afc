//! Placing a surface in the simulation's frame before it is voxelized:
//! units, scale, which axis is up, a rotation and a translation.
//!
//! Meshes come in the units and orientation of the tool that made them (the
//! Stanford bunny is 10 units tall with +y up, CAD parts are in millimetres),
//! while everything downstream works in metres with gravity and
//! `lowest_layer` along z. A [`Placement`] maps a file's coordinates `p` to
//! the simulation's, in this fixed order:
//!
//! 1. **units**: `p * u`, with `u` = 1 (m), 0.01 (cm) or 0.001 (mm);
//! 2. **scale**: multiplied component-wise by `[sx, sy, sz]` (a single number
//!    scales uniformly);
//! 3. **up**: the axis named up becomes +z. `up = y` is a rotation of +90°
//!    about x (`(x, y, z) -> (x, -z, y)`, the usual Y-up to Z-up conversion);
//!    `up = x` a rotation of -90° about y (`(x, y, z) -> (-z, y, x)`);
//!    `up = z` changes nothing;
//! 4. **rotate** `[rx, ry, rz]` (degrees): about the fixed x axis by `rx`,
//!    then about the fixed y axis by `ry`, then about the fixed z axis by
//!    `rz`, all through the origin (the matrix `Rz Ry Rx`), counter-clockwise
//!    looking down the axis toward the origin (right-handed);
//! 5. **translate** `[tx, ty, tz]` (m), last, so it is in the final frame.
//!
//! A mirroring scale (an odd number of negative factors) reverses the
//! triangles' winding, so [`Placement::apply`] flips every triangle back to
//! keep outward normals outward.
//!
//! ```
//! use hexmesh::placement::{Placement, UpAxis, Units};
//! use hexmesh::TriMesh;
//!
//! // A Y-up mesh in centimetres, 10 cm tall, standing at y = 0 ... 10.
//! let mut mesh = TriMesh {
//!     vertices: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 10.0, 0.0], [0.0, 0.0, 1.0]],
//!     triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
//! };
//! let volume = mesh.signed_volume();
//! let placement = Placement { units: Units::Centimetres, up: UpAxis::Y, ..Placement::default() };
//! placement.apply(&mut mesh).unwrap();
//! // Now 0.1 m tall along z, and still outward-wound.
//! let top = mesh.vertices[2];
//! assert!((top[2] - 0.1).abs() < 1e-15 && top[1].abs() < 1e-15);
//! assert!((mesh.signed_volume() - volume * 1e-6).abs() < 1e-18);
//! assert_eq!(placement.describe(), "units cm, up y");
//! ```

use std::fmt;

use thiserror::Error;

use crate::TriMesh;
use crate::load::MAX_COORDINATE;

/// Length unit of a mesh file's coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Deserialize))]
pub enum Units {
    /// Metres (factor 1; `"m"` in a scene).
    #[default]
    #[cfg_attr(feature = "serde", serde(rename = "m"))]
    Metres,
    /// Centimetres (factor 0.01; `"cm"`).
    #[cfg_attr(feature = "serde", serde(rename = "cm"))]
    Centimetres,
    /// Millimetres (factor 0.001; `"mm"`).
    #[cfg_attr(feature = "serde", serde(rename = "mm"))]
    Millimetres,
}

impl Units {
    /// Metres per unit.
    pub fn factor(self) -> f64 {
        match self {
            Units::Metres => 1.0,
            Units::Centimetres => 0.01,
            Units::Millimetres => 0.001,
        }
    }

    /// The unit's symbol (`"m"`, `"cm"`, `"mm"`).
    pub fn symbol(self) -> &'static str {
        match self {
            Units::Metres => "m",
            Units::Centimetres => "cm",
            Units::Millimetres => "mm",
        }
    }

    /// The unit for a symbol (`"m"`, `"cm"`, `"mm"`).
    pub fn from_symbol(s: &str) -> Option<Self> {
        match s {
            "m" => Some(Units::Metres),
            "cm" => Some(Units::Centimetres),
            "mm" => Some(Units::Millimetres),
            _ => None,
        }
    }
}

/// The mesh axis that points up (becomes +z).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Deserialize),
    serde(rename_all = "lowercase")
)]
pub enum UpAxis {
    /// +x is up.
    X,
    /// +y is up (most OBJ exporters, the Stanford models).
    Y,
    /// +z is up: the simulation's own convention, nothing turns.
    #[default]
    Z,
}

impl UpAxis {
    /// The axis name (`"x"`, `"y"`, `"z"`).
    pub fn name(self) -> &'static str {
        match self {
            UpAxis::X => "x",
            UpAxis::Y => "y",
            UpAxis::Z => "z",
        }
    }

    /// The rotation taking this axis to +z (rows).
    fn matrix(self) -> [[f64; 3]; 3] {
        match self {
            UpAxis::Z => IDENTITY,
            // +90° about x.
            UpAxis::Y => [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]],
            // -90° about y.
            UpAxis::X => [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]],
        }
    }
}

const IDENTITY: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// How a mesh file's coordinates map to the simulation's (see the module
/// documentation for the order). The default changes nothing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// Unit of the file's coordinates.
    pub units: Units,
    /// Scale factors along x, y, z (after units; non-zero, finite).
    pub scale: [f64; 3],
    /// The file's up axis.
    pub up: UpAxis,
    /// Rotation angles about the fixed x, y, z axes (degrees), applied in that order.
    pub rotate_degrees: [f64; 3],
    /// Translation (m), applied last.
    pub translate: [f64; 3],
}

impl Default for Placement {
    fn default() -> Self {
        Self {
            units: Units::Metres,
            scale: [1.0; 3],
            up: UpAxis::Z,
            rotate_degrees: [0.0; 3],
            translate: [0.0; 3],
        }
    }
}

/// Why a placement could not be applied.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum PlacementError {
    /// A scale factor is zero or not finite.
    #[error("scale {scale:?}: every factor must be finite and non-zero")]
    BadScale {
        /// The scale given.
        scale: [f64; 3],
    },
    /// An angle or offset is not finite.
    #[error("{what} {value:?} is not finite")]
    NonFinite {
        /// `"rotate"` or `"translate"`.
        what: &'static str,
        /// The value given.
        value: [f64; 3],
    },
    /// The placed mesh lies beyond the coordinates a body can have.
    #[error(
        "the placed mesh reaches {reach:.3e} m from the origin, beyond {limit:e} m: check scale, units and translate"
    )]
    TooFar {
        /// Largest coordinate magnitude after placement (m).
        reach: f64,
        /// The limit ([`MAX_COORDINATE`]).
        limit: f64,
    },
}

fn mat_mul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut c = [[0.0; 3]; 3];
    for (i, row) in c.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    c
}

/// The rotation by `degrees` about coordinate axis `axis` (exact for
/// multiples of 90°, so quarter turns do not leave 1e-17 residues).
fn axis_rotation(axis: usize, degrees: f64) -> [[f64; 3]; 3] {
    let quarter = degrees / 90.0;
    let (s, c) = if quarter == quarter.round() && quarter.abs() < 1e15 {
        match (quarter as i64).rem_euclid(4) {
            0 => (0.0, 1.0),
            1 => (1.0, 0.0),
            2 => (0.0, -1.0),
            _ => (-1.0, 0.0),
        }
    } else {
        degrees.to_radians().sin_cos()
    };
    let (i, j) = ((axis + 1) % 3, (axis + 2) % 3);
    let mut m = IDENTITY;
    m[i][i] = c;
    m[i][j] = -s;
    m[j][i] = s;
    m[j][j] = c;
    m
}

impl Placement {
    /// Whether the placement changes nothing.
    pub fn is_identity(&self) -> bool {
        *self == Placement::default()
    }

    /// Checks that every value is usable.
    pub fn validate(&self) -> Result<(), PlacementError> {
        if self.scale.iter().any(|s| !s.is_finite() || *s == 0.0) {
            return Err(PlacementError::BadScale { scale: self.scale });
        }
        for (what, value) in [
            ("rotate", self.rotate_degrees),
            ("translate", self.translate),
        ] {
            if value.iter().any(|v| !v.is_finite()) {
                return Err(PlacementError::NonFinite { what, value });
            }
        }
        Ok(())
    }

    /// The linear part (rows) and the translation of the map `p -> A p + t`.
    pub fn affine(&self) -> ([[f64; 3]; 3], [f64; 3]) {
        let u = self.units.factor();
        let scale = [
            [u * self.scale[0], 0.0, 0.0],
            [0.0, u * self.scale[1], 0.0],
            [0.0, 0.0, u * self.scale[2]],
        ];
        let [rx, ry, rz] = self.rotate_degrees;
        let rotation = mat_mul(
            &axis_rotation(2, rz),
            &mat_mul(&axis_rotation(1, ry), &axis_rotation(0, rx)),
        );
        let a = mat_mul(&rotation, &mat_mul(&self.up.matrix(), &scale));
        (a, self.translate)
    }

    /// Where a file point lands.
    pub fn apply_point(&self, p: [f64; 3]) -> [f64; 3] {
        let (a, t) = self.affine();
        std::array::from_fn(|i| a[i][0] * p[0] + a[i][1] * p[1] + a[i][2] * p[2] + t[i])
    }

    /// Places `mesh` in the simulation's frame (in place). A mirroring scale
    /// flips every triangle, so the winding stays outward. Fails, leaving
    /// `mesh` unchanged, on an unusable value or a placed mesh beyond
    /// [`MAX_COORDINATE`].
    pub fn apply(&self, mesh: &mut TriMesh) -> Result<(), PlacementError> {
        self.validate()?;
        if self.is_identity() {
            return Ok(());
        }
        let placed: Vec<[f64; 3]> = mesh.vertices.iter().map(|&p| self.apply_point(p)).collect();
        let reach = placed.iter().flatten().fold(0.0f64, |m, c| m.max(c.abs()));
        if reach.is_nan() || reach > MAX_COORDINATE {
            return Err(PlacementError::TooFar {
                reach,
                limit: MAX_COORDINATE,
            });
        }
        mesh.vertices = placed;
        let negatives = self.scale.iter().filter(|s| **s < 0.0).count();
        if negatives % 2 == 1 {
            for t in &mut mesh.triangles {
                t.swap(1, 2);
            }
        }
        Ok(())
    }

    /// One line for summaries: the non-default parts, or `"none"`.
    pub fn describe(&self) -> String {
        self.to_string()
    }
}

impl fmt::Display for Placement {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut parts = Vec::new();
        if self.units != Units::Metres {
            parts.push(format!("units {}", self.units.symbol()));
        }
        if self.scale != [1.0; 3] {
            let [x, y, z] = self.scale;
            parts.push(if x == y && y == z {
                format!("scale {x}")
            } else {
                format!("scale [{x}, {y}, {z}]")
            });
        }
        if self.up != UpAxis::Z {
            parts.push(format!("up {}", self.up.name()));
        }
        if self.rotate_degrees != [0.0; 3] {
            let [x, y, z] = self.rotate_degrees;
            parts.push(format!("rotate [{x}, {y}, {z}] deg"));
        }
        if self.translate != [0.0; 3] {
            let [x, y, z] = self.translate;
            parts.push(format!("translate [{x}, {y}, {z}] m"));
        }
        if parts.is_empty() {
            f.write_str("none")
        } else {
            f.write_str(&parts.join(", "))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: [f64; 3], b: [f64; 3]) -> bool {
        (0..3).all(|i| (a[i] - b[i]).abs() < 1e-12)
    }

    #[test]
    fn up_axes_point_to_z_and_are_rotations() {
        for (up, axis) in [(UpAxis::X, 0), (UpAxis::Y, 1), (UpAxis::Z, 2)] {
            let p = Placement {
                up,
                ..Placement::default()
            };
            let mut e = [0.0; 3];
            e[axis] = 1.0;
            assert_eq!(p.apply_point(e), [0.0, 0.0, 1.0], "{up:?}");
            let (a, _) = p.affine();
            let det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
                - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
                + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
            assert_eq!(det, 1.0, "{up:?}");
        }
    }

    #[test]
    fn order_is_units_scale_up_rotate_translate() {
        let p = Placement {
            units: Units::Millimetres,
            scale: [2.0, 3.0, 4.0],
            up: UpAxis::Y,
            rotate_degrees: [0.0, 0.0, 90.0],
            translate: [1.0, 0.0, 0.0],
        };
        // (1000, 1000, 1000) mm -> (1, 1, 1) m -> (2, 3, 4) -> up y: (2, -4, 3)
        // -> 90° about z: (4, 2, 3) -> + (1, 0, 0).
        assert!(close(p.apply_point([1000.0; 3]), [5.0, 2.0, 3.0]));
        assert_eq!(
            p.describe(),
            "units mm, scale [2, 3, 4], up y, rotate [0, 0, 90] deg, translate [1, 0, 0] m"
        );
    }

    #[test]
    fn rotations_compose_x_then_y_then_z() {
        let p = Placement {
            rotate_degrees: [90.0, 90.0, 0.0],
            ..Placement::default()
        };
        // y -> (about x) z -> (about y) x.
        assert!(close(p.apply_point([0.0, 1.0, 0.0]), [1.0, 0.0, 0.0]));
        let q = Placement {
            rotate_degrees: [30.0, 0.0, 0.0],
            ..Placement::default()
        };
        let r = q.apply_point([0.0, 1.0, 0.0]);
        let (s, c) = 30f64.to_radians().sin_cos();
        assert!(close(r, [0.0, c, s]));
    }

    #[test]
    fn mirroring_keeps_outward_winding() {
        let mut mesh = crate::generate::box_mesh([0.0; 3], [1.0, 2.0, 3.0]);
        let v = mesh.signed_volume();
        Placement {
            scale: [-1.0, 1.0, 1.0],
            ..Placement::default()
        }
        .apply(&mut mesh)
        .unwrap();
        assert!((mesh.signed_volume() - v).abs() < 1e-12);
    }

    #[test]
    fn bad_values_are_refused_and_leave_the_mesh_alone() {
        let mut mesh = crate::generate::box_mesh([0.0; 3], [1.0; 3]);
        let before = mesh.clone();
        for p in [
            Placement {
                scale: [0.0, 1.0, 1.0],
                ..Placement::default()
            },
            Placement {
                rotate_degrees: [f64::NAN, 0.0, 0.0],
                ..Placement::default()
            },
            Placement {
                translate: [2e9, 0.0, 0.0],
                ..Placement::default()
            },
            Placement {
                scale: [1e300; 3],
                ..Placement::default()
            },
        ] {
            assert!(p.apply(&mut mesh).is_err(), "{p:?}");
            assert_eq!(mesh, before);
        }
    }
}
