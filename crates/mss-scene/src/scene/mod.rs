//! Scene files: one TOML file describing a whole simulation job.
//!
//! A scene names a surface mesh, how to voxelize it, the material and the
//! spring parameterization, the fixed regions, loads and prescribed motions,
//! the solver and its time step, the simulated duration and what to write.
//! Every table refuses unknown keys (a typo must not be silently ignored), and
//! every error is one line naming the file, the line and column, and what is
//! wrong (for an unknown key: the list of valid keys).
//!
//! Tables deserialize into the libraries' own types where the library has
//! one (`[material]` is [`mss_core::Material`], every `select` is a
//! [`NodeSelector`]); the others are thin tables whose conversion sits beside
//! them ([`LoadsSection::specs`], [`MotionSpec::constraint`],
//! [`VoxelizeSection::options`], [`SolverSection::damping`]), and every
//! default is the library's. This module checks what needs no physics
//! (ranges, consistency); names (parameterization, integrator) are resolved
//! against a [`Registry`](crate::Registry) when the job is built.
//!
//! ```
//! use mss_scene::scene::{Resolution, Scene};
//! let scene = Scene::from_toml_str(
//!     r#"
//!     [mesh]
//!     path = "builtin:critter"
//!     [material]
//!     young = 5.0e4
//!     poisson = 0.3
//!     density = 1000.0
//!     [[fixed]]
//!     kind = "lowest_layer"
//!     "#,
//!     "example.toml",
//! )
//! .unwrap();
//! assert_eq!(scene.solver.kind, "explicit");
//! assert_eq!(scene.voxelize.resolution(), Resolution::CellsAlongLongestAxis(24));
//!
//! let err = Scene::from_toml_str("[mesh]\npath = \"a.obj\"\ncolour = 1\n", "bad.toml")
//!     .unwrap_err()
//!     .to_string();
//! assert!(err.starts_with("bad.toml:3:1: unknown field `colour`"), "{err}");
//! assert!(err.contains("expected one of `path`"), "{err}");
//! ```

use std::path::{Path, PathBuf};

use mss_core::Material;
use mss_core::constraints::NodeSelector;
use serde::Deserialize;
use thiserror::Error;

mod bodies;
mod constraints;
mod contact;
mod image;
mod key;
mod loads;
mod material;
mod mesh;
mod model;
mod output;
mod solver;
mod voxelize;

pub use bodies::{BodySource, BodySpec, BodyView, SINGLE_BODY_NAME};
pub use constraints::*;
pub use contact::*;
pub use image::*;
pub use key::{KeyError, value_from_str};
pub use loads::*;
pub use material::*;
pub use mesh::*;
pub use model::*;
pub use output::*;
pub use solver::*;
pub use voxelize::*;

/// Largest scene file accepted (bytes): a scene is a few kilobytes; anything
/// much larger is not a scene file.
pub const MAX_SCENE_BYTES: u64 = 4 << 20;

/// Prefix of built-in mesh names in `[mesh] path` (e.g. `"builtin:critter"`).
pub const BUILTIN_PREFIX: &str = "builtin:";

/// Mesh path the bundled default scene uses for the bundled mesh.
pub const BUNDLED_MESH_PATH: &str = "../meshes/critter.obj";

/// The bundled default scene (`data/scenes/default.toml`), run by `mss run`
/// without arguments. Its mesh path is [`BUNDLED_MESH_PATH`].
pub const DEFAULT_SCENE_TOML: &str = include_str!("../../../../data/scenes/default.toml");

/// The bundled default mesh (`data/meshes/critter.obj`), so that the default
/// job runs from any folder.
pub const BUNDLED_CRITTER_OBJ: &[u8] = include_bytes!("../../../../data/meshes/critter.obj");

/// Names of the bundled meshes (`"builtin:NAME"` in a scene): the critter,
/// a cube of edge 1 m and a sphere of diameter 1 m (1,280 triangles), both
/// centred at the origin (`[mesh] scale` and `translate` size and place them).
pub const BUILTIN_MESHES: &[&str] = &["critter", "cube", "sphere"];

/// The commented template scene (`data/scenes/template.toml`) written by `mss init`.
pub const TEMPLATE_SCENE_TOML: &str = include_str!("../../../../data/scenes/template.toml");

/// Why a scene was refused.
#[derive(Debug, Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("cannot read scene file {path}: {source}")]
    Io {
        /// The scene file.
        path: String,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The file is too large to be a scene.
    #[error("{path} is {size} bytes, too large for a scene file (limit {limit} bytes)")]
    TooLarge {
        /// The scene file.
        path: String,
        /// Its size (bytes).
        size: u64,
        /// The limit (bytes).
        limit: u64,
    },
    /// The text is not valid TOML or does not match the scene layout (unknown
    /// key, wrong value type, missing key).
    #[error("{path}:{line}:{column}: {message}{context}")]
    Parse {
        /// The scene file.
        path: String,
        /// 1-based line of the problem (0 if unknown).
        line: usize,
        /// 1-based column of the problem (0 if unknown).
        column: usize,
        /// What is wrong, from the TOML reader (for unknown keys it lists the valid ones).
        message: String,
        /// The offending line's text, as ` (at "...")`, or empty.
        context: String,
    },
    /// A value is out of range or inconsistent with another.
    #[error("{path}: {key}: {message}")]
    Invalid {
        /// The scene file.
        path: String,
        /// The key, as `[table] key`.
        key: String,
        /// What is wrong and what to do.
        message: String,
    },
}

/// A whole simulation job. Tables and their defaults are documented on each
/// field's type; only `[mesh]` and `[material]` are required.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// `[mesh]`: the input surface (required unless the scene has
    /// `[image]` or `[[bodies]]`, where each body has its own).
    #[serde(default)]
    pub mesh: Option<MeshSection>,
    /// `[image]`: a segmented label volume as the body, instead of `[mesh]`.
    #[serde(default)]
    pub image: Option<ImageSection>,
    /// `[voxelize]`: how the surface becomes a cubic lattice.
    #[serde(default)]
    pub voxelize: VoxelizeSection,
    /// `[material]`: Young's modulus `young` (Pa), Poisson's ratio `poisson`
    /// and density `density` (kg/m^3) (required unless the scene has
    /// `[[bodies]]`).
    #[serde(default)]
    pub material: Option<Material>,
    /// `[model]`: the spring parameterization.
    #[serde(default)]
    pub model: ModelSection,
    /// `[[fixed]]`: node sets held at their rest positions.
    #[serde(default)]
    pub fixed: Vec<NodeSelector>,
    /// `[loads]`: gravity, forces, tractions, drag springs.
    #[serde(default)]
    pub loads: LoadsSection,
    /// `[[motions]]`: node sets moved along a prescribed path.
    #[serde(default)]
    pub motions: Vec<MotionSpec>,
    /// `[solver]`: integrator, time step, damping, duration.
    #[serde(default)]
    pub solver: SolverSection,
    /// `[output]`: folder, file kinds and frame schedule.
    #[serde(default)]
    pub output: OutputSection,
    /// `[[regions]]`: cells with their own material (see [`crate::regions`]).
    #[serde(default)]
    pub regions: Vec<RegionSpec>,
    /// `[[obstacles]]`: rigid obstacles the body touches (see [`crate::obstacles`]).
    #[serde(default)]
    pub obstacles: Vec<ObstacleSpec>,
    /// `[contact]`: which points touch them, and contact between bodies.
    #[serde(default)]
    pub contact: ContactSection,
    /// `[[bodies]]`: the bodies of a scene of several (see
    /// [`Scene::bodies`]); empty: the top-level tables are the one body.
    #[serde(default)]
    pub bodies: Vec<BodySpec>,
}

/// Where a scene's mesh comes from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MeshSource {
    /// A file on disk.
    File(PathBuf),
    /// A mesh bundled with the program, by name (e.g. `"critter"`).
    Builtin(String),
}

/// Where a scene came from: a file, or the program's bundled default.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SceneOrigin {
    /// A scene file.
    File(PathBuf),
    /// The scene bundled with the program.
    Bundled,
    /// Text given by a program (not a file), with the name it goes by in
    /// messages; relative mesh paths are relative to the working directory.
    Text(String),
}

impl SceneOrigin {
    /// Name used in messages.
    pub fn display_name(&self) -> String {
        match self {
            SceneOrigin::File(p) => p.display().to_string(),
            SceneOrigin::Bundled => "<bundled default.toml>".to_owned(),
            SceneOrigin::Text(name) => name.clone(),
        }
    }
}

fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// Levenshtein distance between two short names.
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut diagonal = row[0];
        row[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let above = row[j + 1];
            row[j + 1] = (diagonal + usize::from(ca != cb))
                .min(row[j] + 1)
                .min(above + 1);
            diagonal = above;
        }
    }
    row[b.len()]
}

/// For serde's "unknown field `X`, expected one of `a`, `b`" (or an unknown
/// variant), the valid name closest to `X` when it is a likely typo: within
/// a third of its length in edits (at least one).
fn did_you_mean(message: &str) -> Option<String> {
    let (_, rest) = message
        .split_once("unknown field `")
        .or_else(|| message.split_once("unknown variant `"))?;
    let (given, rest) = rest.split_once('`')?;
    let (_, expected) = rest.split_once("expected")?;
    let limit = (given.chars().count() / 3).max(1);
    expected
        .split('`')
        .skip(1)
        .step_by(2)
        .map(|name| (edit_distance(given, name), name))
        .filter(|&(d, _)| d <= limit)
        .min_by_key(|&(d, _)| d)
        .map(|(_, name)| name.to_owned())
}

/// 1-based line and column of byte offset `at` in `text`.
fn line_column(text: &str, at: usize) -> (usize, usize) {
    let at = at.min(text.len());
    let mut at = at;
    while !text.is_char_boundary(at) {
        at -= 1;
    }
    let before = &text[..at];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let column = text[line_start..at].chars().count() + 1;
    (line, column)
}

impl Scene {
    /// Parses and checks a scene; `name` is used in error messages.
    pub fn from_toml_str(text: &str, name: &str) -> Result<Scene, SceneError> {
        let scene: Scene = toml::from_str(text).map_err(|e| {
            let (line, column, context) = match e.span() {
                Some(span) => {
                    let (line, column) = line_column(text, span.start);
                    let src = text.lines().nth(line - 1).unwrap_or("").trim();
                    let src: String = src.chars().take(60).collect();
                    let context = if src.is_empty() {
                        String::new()
                    } else {
                        format!(" (at \"{src}\")")
                    };
                    (line, column, context)
                }
                None => (0, 0, String::new()),
            };
            let mut message = one_line(e.message());
            if let Some(name) = did_you_mean(&message) {
                message.push_str(&format!(" (did you mean `{name}`?)"));
            }
            SceneError::Parse {
                path: name.to_owned(),
                line,
                column,
                message,
                context,
            }
        })?;
        scene.validate(name)?;
        Ok(scene)
    }

    /// Reads, parses and checks a scene file.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let name = path.display().to_string();
        let io = |source| SceneError::Io {
            path: name.clone(),
            source,
        };
        let meta = std::fs::metadata(path).map_err(io)?;
        if meta.is_dir() {
            return Err(SceneError::Io {
                path: name.clone(),
                source: std::io::Error::other("it is a folder, not a scene file"),
            });
        }
        if !meta.is_file() {
            // A device or a pipe would be read forever or block.
            return Err(SceneError::Io {
                path: name.clone(),
                source: std::io::Error::other("it is not a regular file (a device or pipe)"),
            });
        }
        if meta.len() > MAX_SCENE_BYTES {
            return Err(SceneError::TooLarge {
                path: name,
                size: meta.len(),
                limit: MAX_SCENE_BYTES,
            });
        }
        let bytes = std::fs::read(path).map_err(io)?;
        let text = String::from_utf8(bytes).map_err(|e| SceneError::Parse {
            path: name.clone(),
            line: 0,
            column: 0,
            message: format!(
                "the file is not UTF-8 text (invalid byte at offset {}); a scene is a TOML text file",
                e.utf8_error().valid_up_to()
            ),
            context: String::new(),
        })?;
        Self::from_toml_str(&text, &name)
    }

    /// Where the mesh is, for a scene from `origin`: `"builtin:NAME"` names a
    /// bundled mesh; a relative path is relative to the scene file's folder. In
    /// the bundled scene, [`BUNDLED_MESH_PATH`] is the bundled critter.
    pub fn mesh_source(&self, origin: &SceneOrigin) -> MeshSource {
        let path = self.mesh.as_ref().map_or("", |m| m.path.as_str());
        Self::source_of(path, origin)
    }

    /// Where a mesh path of a scene from `origin` points (the rules of
    /// [`Scene::mesh_source`]).
    pub fn source_of(path: &str, origin: &SceneOrigin) -> MeshSource {
        let p = path;
        if let Some(name) = p.strip_prefix(BUILTIN_PREFIX) {
            return MeshSource::Builtin(name.to_owned());
        }
        match origin {
            SceneOrigin::Bundled if p == BUNDLED_MESH_PATH => {
                MeshSource::Builtin("critter".to_owned())
            }
            SceneOrigin::Bundled | SceneOrigin::Text(_) => MeshSource::File(PathBuf::from(p)),
            SceneOrigin::File(scene) => {
                let base = scene.parent().unwrap_or(Path::new(""));
                MeshSource::File(base.join(p))
            }
        }
    }

    /// Checks ranges and consistency that need no physics: each table by
    /// its own `check`, then what involves two tables. Material and
    /// parameterization are checked by the library when the model is built,
    /// names (parameterization, integrator, rule, kinds) against the
    /// registry when the job is built.
    pub fn validate(&self, name: &str) -> Result<(), SceneError> {
        let invalid = |key: String, message: String| SceneError::Invalid {
            path: name.to_owned(),
            key,
            message,
        };
        let in_table = |table: &str, e: KeyError| invalid(e.scene_key(table), e.message);
        // An entry of a list of tables: `[[fixed]] #2`, and its key if any.
        let in_list = |list: &str, i: usize, e: KeyError| {
            let entry = format!("{list} #{}", i + 1);
            let e = e.within(&entry);
            invalid(e.key, e.message)
        };
        self.check_tables_of_bodies(&invalid)?;
        self.loads
            .check()
            .map_err(|e| match e.key.split_once(" #") {
                // `forces #1` is the list `[[loads.forces]]`.
                Some((list, n)) => invalid(format!("[[loads.{list}]] #{n}"), e.message),
                None => in_table("[loads]", e),
            })?;
        self.solver.check().map_err(|e| in_table("[solver]", e))?;
        self.output.check().map_err(|e| in_table("[output]", e))?;
        for (i, o) in self.obstacles.iter().enumerate() {
            o.check().map_err(|e| in_list("[[obstacles]]", i, e))?;
        }
        self.contact.check().map_err(|e| in_table("[contact]", e))?;
        self.check_plane(&invalid)?;
        if self.output.checkpoint_every.is_some() && self.solver.is_static() {
            return Err(invalid(
                "[output] checkpoint_every".into(),
                "a static solve is one step and has nothing to resume; remove the key or use a time-stepping solver".into(),
            ));
        }
        Ok(())
    }
}

impl Scene {
    /// Whether the scene's body is 2D (`[model] dimension = 2`).
    pub fn is_plane(&self) -> bool {
        self.bodies.is_empty() && self.model.is_plane()
    }

    /// What a 2D scene may hold: one body (not `[[bodies]]`), vectors in
    /// the x-y plane (gravity, forces, tractions, motions), the explicit,
    /// implicit or static solver, single precision only for the explicit.
    fn check_plane(
        &self,
        invalid: &dyn Fn(String, String) -> SceneError,
    ) -> Result<(), SceneError> {
        if self.bodies.iter().any(|b| b.model.is_plane()) {
            return Err(invalid(
                "[[bodies]] [model] dimension".into(),
                "= 2; a 2D body is a scene of its own (top-level [mesh] and [model] dimension = 2), not one of [[bodies]]".into(),
            ));
        }
        if !self.is_plane() {
            return Ok(());
        }
        // The first entry of a list table whose vector leaves the plane.
        let in_plane = |list: &str,
                        field: &str,
                        verb: &str,
                        vectors: &mut dyn Iterator<Item = [f64; 3]>|
         -> Result<(), SceneError> {
            match vectors.enumerate().find(|(_, v)| v[2] != 0.0) {
                Some((i, v)) => Err(invalid(
                    format!("{list} #{} {field}", i + 1),
                    format!("= {v:?}; a 2D body {verb} in the x-y plane (z = 0)"),
                )),
                None => Ok(()),
            }
        };
        in_plane(
            "[[motions]]",
            "displacement",
            "moves",
            &mut self.motions.iter().map(|m| m.displacement),
        )?;
        if self.solver.precision != mss_core::Precision::F64 && self.solver.kind == "implicit" {
            return Err(invalid(
                "[solver] precision".into(),
                format!(
                    "= \"{}\" with kind = \"implicit\"; the precision is the explicit step's: Newton's method needs f64 forces and tangents",
                    self.solver.precision.name()
                ),
            ));
        }
        in_plane(
            "[[loads.tractions]]",
            "traction",
            "takes tractions",
            &mut self.loads.tractions.iter().map(|t| t.traction),
        )?;
        if let Some(g) = self.loads.gravity
            && g[2] != 0.0
        {
            return Err(invalid(
                "[loads] gravity".into(),
                format!(
                    "= {g:?}; a 2D body lies in the x-y plane, where gravity along z does nothing: give it in the plane, e.g. [0.0, -9.81, 0.0]"
                ),
            ));
        }
        in_plane(
            "[[loads.forces]]",
            "force",
            "takes forces",
            &mut self.loads.forces.iter().map(|f| f.force),
        )?;
        if !(self.solver.is_static()
            || self.solver.kind == "explicit"
            || self.solver.kind == "implicit")
        {
            return Err(invalid(
                "[solver] kind".into(),
                format!(
                    "= {:?}; a 2D body runs with \"explicit\", \"implicit\" or \"static\"",
                    self.solver.kind
                ),
            ));
        }
        Ok(())
    }

    /// The checks of each body's tables, and of `[[bodies]]` against the
    /// top level: with bodies, the tables that belong to a body are not
    /// given at the top level; without, `[mesh]` and `[material]` are.
    fn check_tables_of_bodies(
        &self,
        invalid: &dyn Fn(String, String) -> SceneError,
    ) -> Result<(), SceneError> {
        if self.bodies.is_empty() {
            match (&self.mesh, &self.image) {
                (None, None) => {
                    return Err(invalid(
                        "[mesh]".into(),
                        "missing field `mesh`: a scene needs a [mesh] table (path = \"...\"), an [image] table, or [[bodies]] each with its own".into(),
                    ));
                }
                (Some(_), Some(_)) => {
                    return Err(invalid(
                        "[image]".into(),
                        "a body is made from a [mesh] or from an [image], not both: remove one"
                            .into(),
                    ));
                }
                _ => {}
            }
            if self.material.is_none() {
                return Err(invalid(
                    "[material]".into(),
                    "missing field `material`: a scene needs a [material] table (young, poisson, density), or [[bodies]] each with its own".into(),
                ));
            }
        } else {
            // What is given at the top level, and where it goes in a body.
            let per_body = [
                ("[mesh]", self.mesh.is_some(), "[bodies.mesh]"),
                ("[image]", self.image.is_some(), "[bodies.image]"),
                ("[material]", self.material.is_some(), "[bodies.material]"),
                (
                    "[voxelize]",
                    self.voxelize != VoxelizeSection::default(),
                    "[bodies.voxelize]",
                ),
                (
                    "[model]",
                    self.model != ModelSection::default(),
                    "[bodies.model]",
                ),
                ("[[fixed]]", !self.fixed.is_empty(), "[[bodies.fixed]]"),
                (
                    "[[motions]]",
                    !self.motions.is_empty(),
                    "[[bodies.motions]]",
                ),
                (
                    "[[regions]]",
                    !self.regions.is_empty(),
                    "[[bodies.regions]]",
                ),
                (
                    "[contact] self_contact",
                    self.contact.self_contact,
                    "self_contact in a [[bodies]] table",
                ),
            ];
            if let Some((table, _, there)) = per_body.iter().find(|(_, given, _)| *given) {
                return Err(invalid(
                    (*table).into(),
                    format!(
                        "with [[bodies]], {table} belongs to each body: move it into the [[bodies]] tables (as {there})"
                    ),
                ));
            }
            for (i, b) in self.bodies.iter().enumerate() {
                bodies::check_name(&b.name).map_err(|e| {
                    let e = e.within(&format!("[[bodies]] #{}", i + 1));
                    invalid(e.key, e.message)
                })?;
                if self.bodies[..i].iter().any(|o| o.name == b.name) {
                    return Err(invalid(
                        format!("[[bodies]] #{} name", i + 1),
                        format!(
                            "= {:?}: another body has that name; names must differ (they name the output files)",
                            b.name
                        ),
                    ));
                }
                if b.mesh.is_some() == b.image.is_some() {
                    return Err(invalid(
                        format!("[[bodies]] #{} ({})", i + 1, b.name),
                        "a body needs a [bodies.mesh] or a [bodies.image] table (one of them)"
                            .into(),
                    ));
                }
                if b.loads.gravity.is_some() {
                    return Err(invalid(
                        format!("[[bodies]] #{} ({}) [loads] gravity", i + 1, b.name),
                        "gravity is scene-wide: set it in the top-level [loads]".into(),
                    ));
                }
            }
        }
        for body in self.bodies() {
            let in_table =
                |table: &str, e: KeyError| invalid(body.key(&e.scene_key(table)), e.message);
            let in_list = |list: &str, i: usize, e: KeyError| {
                let e = e.within(&format!("{list} #{}", i + 1));
                invalid(body.key(&e.key), e.message)
            };
            match body.source {
                BodySource::Mesh(mesh) => mesh.check().map_err(|e| in_table("[mesh]", e))?,
                BodySource::Image(image) => image.check().map_err(|e| in_table("[image]", e))?,
            }
            body.voxelize
                .check()
                .map_err(|e| in_table("[voxelize]", e))?;
            body.model.check().map_err(|e| in_table("[model]", e))?;
            if !body.model.is_plane() && body.voxelize.cell_sides.is_some() {
                return Err(invalid(
                    body.key("[voxelize] cell_size"),
                    "two sides are for a 2D body ([model] dimension = 2); the 3D model's cells are cubes: give one length".into(),
                ));
            }
            if let Some(n) = body.voxelize.cells_per_axis
                && !body.model.is_plane()
            {
                return Err(invalid(
                    body.key("[voxelize] cells"),
                    format!(
                        "= {n:?}; cells per axis are for a 2D body ([model] dimension = 2); the 3D model's cells are cubes: give the number along the longest axis"
                    ),
                ));
            }
            check_material(&body.material).map_err(|e| in_table("[material]", e))?;
            for (i, s) in body.fixed.iter().enumerate() {
                check_selector(s).map_err(|e| in_list("[[fixed]]", i, e))?;
            }
            for (i, r) in body.regions.iter().enumerate() {
                r.check().map_err(|e| in_list("[[regions]]", i, e))?;
            }
            for (i, m) in body.motions.iter().enumerate() {
                m.check().map_err(|e| in_list("[[motions]]", i, e))?;
            }
            if let Some(loads) = body.loads {
                loads.check().map_err(|e| match e.key.split_once(" #") {
                    Some((list, n)) => {
                        invalid(body.key(&format!("[[loads.{list}]] #{n}")), e.message)
                    }
                    None => in_table("[loads]", e),
                })?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mss_core::constraints::{Axis, Side};

    const MIN: &str = "[mesh]\npath = \"m.obj\"\n[material]\nyoung = 1e4\npoisson = 0.3\n\
                       density = 1000.0\n";

    fn err(text: &str) -> String {
        Scene::from_toml_str(text, "s.toml")
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn minimal_scene_gets_documented_defaults() {
        let s = Scene::from_toml_str(MIN, "s.toml").unwrap();
        assert_eq!(s.voxelize, VoxelizeSection::default());
        assert_eq!(s.solver, SolverSection::default());
        assert_eq!(s.output, OutputSection::default());
        assert_eq!(s.model.parameterization, "volumetric-barrier+hg");
        assert_eq!(s.model.hourglass, Some(1.0));
        assert!(s.fixed.is_empty());
        let s = Scene::from_toml_str(
            &format!("{MIN}[model]\nparameterization = \"volumetric+hg\"\nhourglass = 0.25\n"),
            "s.toml",
        )
        .unwrap();
        assert_eq!(s.model.parameterization, "volumetric+hg");
        assert_eq!(s.model.hourglass, Some(0.25));
        assert!(err(&format!("{MIN}[model]\nhourglass = \"strong\"\n")).contains("hourglass"));
        // A named parameterization keeps its own hourglass default; a factor
        // alone applies to the default parameterization.
        let s = Scene::from_toml_str(
            &format!("{MIN}[model]\nparameterization = \"paper+hg\"\n"),
            "s.toml",
        )
        .unwrap();
        assert_eq!(
            (s.model.parameterization.as_str(), s.model.hourglass),
            ("paper+hg", None)
        );
        let s =
            Scene::from_toml_str(&format!("{MIN}[model]\nhourglass = 0.3\n"), "s.toml").unwrap();
        assert_eq!(
            (s.model.parameterization.as_str(), s.model.hourglass),
            ("volumetric-barrier+hg", Some(0.3))
        );
        let e = err(&format!("{MIN}[model]\nhourglas = 0.3\n"));
        assert!(
            e.contains("unknown field `hourglas`") && e.contains("s.toml:8"),
            "{e}"
        );
    }

    #[test]
    fn unknown_key_names_key_valid_keys_and_position() {
        let e = err(&format!("{MIN}colour = 3\n"));
        assert!(e.starts_with("s.toml:7:1: unknown field `colour`"), "{e}");
        assert!(
            e.contains("`young`") && e.contains("`poisson`") && e.contains("`density`"),
            "{e}"
        );
        assert!(!e.contains('\n'), "{e}");
        // Unknown keys inside a tagged selector table too.
        let e = err(&format!(
            "{MIN}[[fixed]]\nkind = \"box\"\nmin = [0,0,0]\nmax = [1,1,1]\nsize = 2\n"
        ));
        assert!(e.contains("unknown field `size`"), "{e}");
        assert!(e.contains("`min`"), "{e}");
        let e = err(&format!(
            "{MIN}[[fixed]]\nkind = \"lowest_layer\"\nheight = 2\n"
        ));
        assert!(e.contains("unknown field `height`"), "{e}");
        let e = err(&format!("{MIN}[[fixed]]\nkind = \"blob\"\n"));
        assert!(
            e.contains("unknown variant `blob`") && e.contains("`box`"),
            "{e}"
        );
        let e = err(&format!("{MIN}[extras]\na = 1\n"));
        assert!(
            e.contains("unknown field `extras`") && e.contains("`mesh`"),
            "{e}"
        );
    }

    #[test]
    fn wrong_types_and_missing_keys_are_reported() {
        let e = err(
            "[mesh]\npath = \"m.obj\"\n[material]\nyoung = \"soft\"\npoisson = 0.3\ndensity = 1.0\n",
        );
        assert!(e.starts_with("s.toml:4:"), "{e}");
        assert!(e.contains("invalid type"), "{e}");
        let e = err("[mesh]\npath = \"m.obj\"\n");
        assert!(e.contains("missing field `material`"), "{e}");
        let e = err("[mesh\npath = 1");
        assert!(e.starts_with("s.toml:1:"), "{e}");
        let e = err(&format!("{MIN}[solver]\ndt = \"fast\"\n"));
        assert!(e.contains("\"auto\" or a time step"), "{e}");
    }

    #[test]
    fn range_checks_name_the_key() {
        let cases = [
            ("[solver]\nduration = -1.0\n", "[solver] duration"),
            ("[solver]\ndt = 0\n", "[solver] dt"),
            ("[solver]\nsafety = 1.5\n", "[solver] safety"),
            ("[voxelize]\ncells = 0\n", "[voxelize] cells"),
            ("[voxelize]\ncells = 4\ncell_size = 0.1\n", "not both"),
            ("[output]\nevery_steps = 0\n", "[output] every_steps"),
            (
                "[[fixed]]\nkind = \"box\"\nmin = [1,0,0]\nmax = [0,1,1]\n",
                "min <= max",
            ),
            ("[[fixed]]\nkind = \"indices\"\nnodes = []\n", "is empty"),
        ];
        for (extra, needle) in cases {
            let e = err(&format!("{MIN}{extra}"));
            assert!(e.contains(needle), "{extra:?} -> {e}");
            assert!(!e.contains('\n'));
        }
    }

    #[test]
    fn mesh_sources_resolve() {
        let mut s = Scene::from_toml_str(MIN, "s.toml").unwrap();
        let origin = SceneOrigin::File(PathBuf::from("dir/scene.toml"));
        assert_eq!(
            s.mesh_source(&origin),
            MeshSource::File(PathBuf::from("dir/m.obj"))
        );
        s.mesh.as_mut().unwrap().path = BUNDLED_MESH_PATH.into();
        assert_eq!(
            s.mesh_source(&SceneOrigin::Bundled),
            MeshSource::Builtin("critter".into())
        );
        s.mesh.as_mut().unwrap().path = "builtin:critter".into();
        assert_eq!(
            s.mesh_source(&origin),
            MeshSource::Builtin("critter".into())
        );
    }

    #[test]
    fn time_step_accepts_auto_and_numbers() {
        let s = Scene::from_toml_str(&format!("{MIN}[solver]\ndt = 1e-4\n"), "s").unwrap();
        assert_eq!(s.solver.dt, TimeStep::Seconds(1e-4));
        let s = Scene::from_toml_str(&format!("{MIN}[solver]\ndt = \"auto\"\n"), "s").unwrap();
        assert_eq!(s.solver.dt, TimeStep::Auto);
    }

    #[test]
    fn every_table_parses() {
        let text = format!(
            "{MIN}[[fixed]]\nkind = \"face\"\nface = \"x-\"\n\
             [[fixed]]\nkind = \"plane\"\naxis = \"y\"\nvalue = 0.5\nside = \"above\"\n\
             [[fixed]]\nkind = \"box\"\nmin = [0, 0, 0]\nmax = [0.1, 1, 1]\nrelative = true\n\
             [loads]\ngravity = [0, 0, -9.81]\n\
             [[loads.forces]]\nselect = {{ kind = \"indices\", nodes = [1, 2] }}\n\
             force = [0, 0, -1]\nper_node = true\n\
             [[loads.tractions]]\nmin = [0, 0, 0]\nmax = [1, 1, 1]\ntraction = [1, 0, 0]\n\
             [[loads.drags]]\nselect = {{ kind = \"lowest_layer\" }}\ntarget = [0, 0, 1]\n\
             stiffness = 2.0\n\
             [[motions]]\nselect = {{ kind = \"face\", face = \"z+\" }}\n\
             displacement = [0, 0, -0.01]\nramp = 0.5\n\
             [solver]\nkind = \"static\"\n"
        );
        let s = Scene::from_toml_str(&text, "s.toml").unwrap();
        assert_eq!(s.fixed.len(), 3);
        assert_eq!(
            s.fixed[1],
            NodeSelector::Plane {
                axis: Axis::Y,
                value: 0.5,
                side: Side::Above
            }
        );
        assert!(s.loads.forces[0].per_node);
        assert_eq!(s.loads.tractions.len(), 1);
        assert_eq!(s.loads.drags[0].stiffness, 2.0);
        assert_eq!(s.motions[0].ramp, Some(0.5));
        assert!(s.solver.is_static());
    }

    #[test]
    fn bundled_scenes_parse() {
        let d = Scene::from_toml_str(DEFAULT_SCENE_TOML, "default.toml").unwrap();
        assert_eq!(d.mesh.as_ref().unwrap().path, BUNDLED_MESH_PATH);
        assert_eq!(d.fixed, vec![NodeSelector::LowestLayer]);
        assert_eq!(d.loads.gravity, Some([0.0, 0.0, -9.81]));
        let t = Scene::from_toml_str(TEMPLATE_SCENE_TOML, "template.toml").unwrap();
        assert_eq!(
            t.mesh_source(&SceneOrigin::File("x/s.toml".into())),
            MeshSource::Builtin("critter".into())
        );
        // The template shows every default: it differs from a minimal scene only
        // where marked "example".
        assert_eq!(
            t.voxelize,
            VoxelizeSection {
                cells: Some(24),
                ..Default::default()
            }
        );
        assert_eq!(t.output.every_time, Some(0.05));
    }

    #[test]
    fn typos_get_the_closest_valid_name() {
        let e = err(&format!("{MIN}[model]\nhourglas = 0.3\n"));
        assert!(e.contains("(did you mean `hourglass`?)"), "{e}");
        let e = err(&format!("{MIN}[solver]\ndurration = 1.0\n"));
        assert!(e.contains("(did you mean `duration`?)"), "{e}");
        let e = err(&format!("{MIN}[[fixed]]\nkind = \"lowest_layr\"\n"));
        assert!(e.contains("(did you mean `lowest_layer`?)"), "{e}");
        // Nothing close: no guess.
        let e = err(&format!("{MIN}colour = 3\n"));
        assert!(!e.contains("did you mean"), "{e}");
        assert_eq!(edit_distance("kitten", "sitting"), 3);
        assert_eq!(edit_distance("", "abc"), 3);
    }

    #[test]
    fn line_column_is_one_based() {
        assert_eq!(line_column("ab\ncd", 0), (1, 1));
        assert_eq!(line_column("ab\ncd", 4), (2, 2));
        assert_eq!(line_column("é\nx", 1), (1, 1));
    }
}
