//! `[mesh]`: the surface file and its placement (units, scale, up axis,
//! rotation, translation).

use hexmesh::placement::{Placement, PlacementError};
pub use hexmesh::placement::{Units, UpAxis};
use serde::Deserialize;

use super::key::KeyError;

/// `[mesh]`: the input surface (OBJ, STL, PLY, VTK) and where it is placed
/// before voxelizing: `units`, `scale`, `up`, `rotate`, `translate`, applied
/// in that order (see [`hexmesh::placement`]).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshSection {
    /// Path of the surface mesh, relative to the scene file's folder, or a
    /// built-in mesh as `"builtin:NAME"` (`"builtin:critter"`).
    pub path: String,
    /// Unit of the file's coordinates: `"m"` (default), `"cm"` or `"mm"`.
    #[serde(default)]
    pub units: Units,
    /// Scale factor after units: one number, or `[sx, sy, sz]` (default 1).
    #[serde(default)]
    pub scale: ScaleKey,
    /// The file's up axis, turned to +z: `"x"`, `"y"` or `"z"` (default).
    #[serde(default)]
    pub up: UpAxis,
    /// Rotation about the fixed x, then y, then z axis (degrees, default 0).
    #[serde(default)]
    pub rotate: [f64; 3],
    /// Translation applied last (m, default 0).
    #[serde(default)]
    pub translate: [f64; 3],
}

impl MeshSection {
    /// Checks the keys: a non-empty `path`, and a placement that applies
    /// (finite, non-zero scale; finite rotation and translation).
    pub fn check(&self) -> Result<(), KeyError> {
        let bad = |key: &str, message: String| Err(KeyError::new(key, message));
        if self.path.trim().is_empty() {
            return bad(
                "path",
                "is empty; give the path of a surface mesh file (OBJ, STL, PLY, VTK; \
                 relative to the scene file) or \"builtin:critter\""
                    .into(),
            );
        }
        if let Err(e) = self.placement().validate() {
            let key = match e {
                PlacementError::BadScale { .. } => "scale",
                PlacementError::NonFinite { what: "rotate", .. } => "rotate",
                _ => "translate",
            };
            return bad(key, e.to_string());
        }
        Ok(())
    }

    /// The placement these keys describe.
    pub fn placement(&self) -> Placement {
        Placement {
            units: self.units,
            scale: match self.scale {
                ScaleKey::Uniform(s) => [s; 3],
                ScaleKey::PerAxis(s) => s,
            },
            up: self.up,
            rotate_degrees: self.rotate,
            translate: self.translate,
        }
    }
}

/// `[mesh] scale`: one factor or one per axis.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(untagged, expecting = "a number or an array of 3 numbers")]
pub enum ScaleKey {
    /// The same factor along every axis.
    Uniform(f64),
    /// Factors along x, y, z.
    PerAxis([f64; 3]),
}

impl Default for ScaleKey {
    fn default() -> Self {
        ScaleKey::Uniform(1.0)
    }
}
