//! `[[bodies]]`: a scene of several bodies, each with its own mesh,
//! lattice, material, model, held nodes, motions and loads; what the
//! bodies share (gravity and the other top-level `[loads]`, `[[obstacles]]`,
//! `[contact]`, `[solver]`, `[output]`) stays at the top level. A scene
//! without `[[bodies]]` is one body made of its top-level tables;
//! [`Scene::bodies`] gives either kind as the same [`BodyView`]s.

use mss_core::Material;
use mss_core::constraints::{ConstraintSpec, NodeSelector};
use serde::Deserialize;

use super::key::KeyError;
use super::{
    ImageSection, LoadsSection, MeshSection, ModelSection, MotionSpec, RegionSpec, Scene,
    VoxelizeSection,
};

/// One `[[bodies]]` table.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodySpec {
    /// Its name: output files and messages use it (letters, digits, `-`
    /// and `_`; unique in the scene).
    pub name: String,
    /// `[bodies.mesh]`: its surface and placement, as `[mesh]`.
    #[serde(default)]
    pub mesh: Option<MeshSection>,
    /// `[bodies.image]`: a label volume instead, as `[image]`.
    #[serde(default)]
    pub image: Option<ImageSection>,
    /// `[bodies.voxelize]`: as `[voxelize]`.
    #[serde(default)]
    pub voxelize: VoxelizeSection,
    /// `[bodies.material]`: as `[material]`.
    pub material: Material,
    /// `[bodies.model]`: as `[model]`.
    #[serde(default)]
    pub model: ModelSection,
    /// `[[bodies.fixed]]`: its held node sets, as `[[fixed]]`.
    #[serde(default)]
    pub fixed: Vec<NodeSelector>,
    /// `[[bodies.motions]]`: as `[[motions]]`.
    #[serde(default)]
    pub motions: Vec<MotionSpec>,
    /// `[[bodies.regions]]`: as `[[regions]]`.
    #[serde(default)]
    pub regions: Vec<RegionSpec>,
    /// `[bodies.loads]`: forces, tractions, drags and custom loads on this
    /// body's nodes (gravity is scene-wide: the top-level `[loads]`).
    #[serde(default)]
    pub loads: LoadsSection,
    /// Whether the body touches itself (a body that folds onto itself;
    /// default false).
    #[serde(default)]
    pub self_contact: bool,
}

/// One body of a scene, from `[[bodies]]` or from the top-level tables.
#[derive(Debug, Clone, Copy)]
pub struct BodyView<'a> {
    /// Its name (`"body"` for a scene without `[[bodies]]`).
    pub name: &'a str,
    /// Its index in `[[bodies]]` (`None`: the top-level tables).
    pub index: Option<usize>,
    /// What it is made from.
    pub source: BodySource<'a>,
    /// How it is voxelized.
    pub voxelize: &'a VoxelizeSection,
    /// Its material.
    pub material: Material,
    /// Its parameterization.
    pub model: &'a ModelSection,
    /// Its held node sets.
    pub fixed: &'a [NodeSelector],
    /// Its prescribed motions.
    pub motions: &'a [MotionSpec],
    /// Its regions.
    pub regions: &'a [RegionSpec],
    /// Its own loads (`None`: the top-level `[loads]` are its loads).
    pub loads: Option<&'a LoadsSection>,
    /// Whether it touches itself.
    pub self_contact: bool,
}

/// What a body is made from: a surface mesh or a label image.
#[derive(Debug, Clone, Copy)]
pub enum BodySource<'a> {
    /// `[mesh]`.
    Mesh(&'a MeshSection),
    /// `[image]`.
    Image(&'a ImageSection),
}

impl BodySource<'_> {
    /// Where its meshes (the body's, its regions' and obstacles') land.
    pub fn placement(&self) -> hexmesh::Placement {
        match self {
            BodySource::Mesh(m) => m.placement(),
            BodySource::Image(i) => i.placement(),
        }
    }

    /// The table's name in a scene (`"[mesh]"`, `"[image]"`).
    pub fn table(&self) -> &'static str {
        match self {
            BodySource::Mesh(_) => "[mesh]",
            BodySource::Image(_) => "[image]",
        }
    }
}

/// Name of the one body of a scene without `[[bodies]]`.
pub const SINGLE_BODY_NAME: &str = "body";

impl BodyView<'_> {
    /// A key of this body's tables as a scene file names it:
    /// `[mesh] path`, or `[[bodies]] #2 [mesh] path` in a scene of bodies.
    pub fn key(&self, key: &str) -> String {
        match self.index {
            None => key.to_owned(),
            Some(i) => format!("[[bodies]] #{} ({}) {key}", i + 1, self.name),
        }
    }

    /// Its boundary conditions: `fixed` sets, then `motions` (over a run of
    /// `duration` seconds).
    pub fn constraint_specs(&self, duration: f64) -> Vec<ConstraintSpec> {
        self.fixed
            .iter()
            .cloned()
            .map(ConstraintSpec::fixed)
            .chain(self.motions.iter().map(|m| m.constraint(duration)))
            .collect()
    }
}

/// Checks a body name: non-empty, at most 64 characters of letters, digits,
/// `-` and `_` (it becomes part of file names).
pub(crate) fn check_name(name: &str) -> Result<(), KeyError> {
    let ok = !name.is_empty()
        && name.len() <= 64
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
    if ok {
        Ok(())
    } else {
        Err(KeyError::new(
            "name",
            format!(
                "= {name:?}; a body's name is 1 to 64 letters, digits, '-' or '_' (it names its output files)"
            ),
        ))
    }
}

impl Scene {
    /// The bodies of the scene: its `[[bodies]]`, or the one body of its
    /// top-level tables. A validated scene has at least one.
    pub fn bodies(&self) -> Vec<BodyView<'_>> {
        if !self.bodies.is_empty() {
            return self
                .bodies
                .iter()
                .enumerate()
                .filter_map(|(i, b)| {
                    let source = match (&b.mesh, &b.image) {
                        (Some(m), _) => BodySource::Mesh(m),
                        (None, Some(image)) => BodySource::Image(image),
                        (None, None) => return None,
                    };
                    Some((i, b, source))
                })
                .map(|(i, b, source)| BodyView {
                    name: &b.name,
                    index: Some(i),
                    source,
                    voxelize: &b.voxelize,
                    material: b.material,
                    model: &b.model,
                    fixed: &b.fixed,
                    motions: &b.motions,
                    regions: &b.regions,
                    loads: Some(&b.loads),
                    self_contact: b.self_contact,
                })
                .collect();
        }
        let source = match (&self.mesh, &self.image) {
            (Some(m), _) => BodySource::Mesh(m),
            (None, Some(image)) => BodySource::Image(image),
            (None, None) => return Vec::new(),
        };
        match self.material {
            Some(material) => vec![BodyView {
                name: SINGLE_BODY_NAME,
                index: None,
                source,
                voxelize: &self.voxelize,
                material,
                model: &self.model,
                fixed: &self.fixed,
                motions: &self.motions,
                regions: &self.regions,
                loads: None,
                self_contact: self.contact.self_contact,
            }],
            _ => Vec::new(),
        }
    }

    /// Whether the scene has `[[bodies]]` (several bodies, or one named).
    pub fn has_bodies(&self) -> bool {
        !self.bodies.is_empty()
    }
}
